// `umvs eval cloud --gt-depth` and `umvs eval depth --sparsification` as a user runs them.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "cli_test_util.h"
#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/ply.h"

namespace umvs {
namespace {

// Every view's exact depth of a small rendered room as one cloud, moved by `shift` metres along x.
PointCloud scene_points(const std::string& dir, float shift) {
  MvsFolder folder(dir);
  PointCloud cloud;
  for (const auto& pair : folder.pairs()) {
    const auto depth = read_pfm(folder.depth_gt_path(pair.ref));
    Camera camera = folder.load_view(pair.ref).cam.camera;
    cloud.append(depth_map_points(depth, camera, 1));
  }
  for (auto& p : cloud.points) p.x() += shift;
  return cloud;
}

TEST(EvalCloudCli, SensorDepthIsTheReference) {
  const std::string dir = test::scene("eval_gt_depth");
  const std::string out = test::temp_dir("eval_gt_depth_out");
  write_ply(out + "/same.ply", scene_points(dir, 0.0f));
  write_ply(out + "/shifted.ply", scene_points(dir, 0.5f));
  const auto fscore = [&](const std::string& cloud) {
    const auto r = test::run_umvs("eval cloud --est " + out + "/" + cloud + " --gt-depth " + dir + " --thresholds 0.05 --gt-stride 1 --gt-spacing 0 --json",
                                  "2>/dev/null");
    EXPECT_EQ(r.status, 0) << r.output;
    return nlohmann::json::parse(r.output)["fscore"][0].get<double>();
  };
  EXPECT_GT(fscore("same.ply"), 0.999);  // every pixel of every view: the same points
  EXPECT_LT(fscore("shifted.ply"), 0.3);  // 50 cm off: close only where the room's walls run along x

  const auto both = test::run_umvs("eval cloud --est " + out + "/same.ply --gt " + out + "/same.ply --gt-depth " + dir);
  EXPECT_NE(both.status, 0);
  EXPECT_TRUE(test::contains(both.output, "give one of --gt CLOUD and --gt-depth FOLDER")) << both.output;
  const auto no_depth = test::run_umvs("eval cloud --est " + out + "/same.ply --gt-depth " + out);
  EXPECT_NE(no_depth.status, 0);
  EXPECT_TRUE(test::contains(no_depth.output, "has no depth_gt/")) << no_depth.output;
}

TEST(EvalDepthCli, SparsificationNeedsTheConfidenceMaps) {
  const std::string dir = test::scene("eval_sparsification");
  // The ground truth as its own estimate, with a confidence that is highest where depth is nearest.
  const std::string est = test::temp_dir("eval_sparsification_est");
  std::filesystem::create_directories(est + "/depth_est");
  std::filesystem::create_directories(est + "/confidence");
  std::filesystem::create_directories(est + "/cams");
  MvsFolder folder(dir);
  for (const auto& pair : folder.pairs()) {
    const std::string stem = view_file_stem(pair.ref);
    const auto gt = read_pfm(folder.depth_gt_path(pair.ref));
    // 20 % too far wherever the depth is above its median, and confident there: a bad ranking.
    const auto far = gt > gt.median();
    write_pfm(est + "/depth_est/" + stem + ".pfm", gt * (1 + 0.2 * far.to(torch::kFloat32)));
    write_pfm(est + "/confidence/" + stem + ".pfm", far.to(torch::kFloat32) * 0.5 + 0.4);
    write_cam_file(est + "/cams/" + stem + "_cam.txt", folder.load_view(pair.ref).cam);
  }
  const auto r = test::run_umvs("eval depth --est " + est + " --gt " + dir + " --sparsification --json", "2>/dev/null");
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_GT(j["sparsification"]["ause"].get<double>(), 0.04);         // the confident half is the wrong half
  EXPECT_NEAR(j["confident"][0]["within"].get<double>(), 0.0, 1e-9);  // >= 0.5: all 20 % off
  EXPECT_NEAR(j["confident"][0]["image_share"].get<double>(), 0.5, 0.05);
  std::filesystem::remove_all(est + "/confidence");
  const auto missing = test::run_umvs("eval depth --est " + est + " --gt " + dir + " --sparsification");
  EXPECT_NE(missing.status, 0);
  EXPECT_TRUE(test::contains(missing.output, "--sparsification needs the confidence maps")) << missing.output;
}

}  // namespace
}  // namespace umvs
