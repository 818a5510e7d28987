// Folder inference (jobs/folder_inference.h) as a library call: what it writes, what it skips and
// what it refuses before writing anything.
#include <gtest/gtest.h>
#include <torch/types.h>

#include <filesystem>
#include <sstream>

#include "test_util.h"
#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/jobs/folder_inference.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;

const std::string kShippedModel = std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt";

TEST(FolderInference, WritesAFolderThatScoresAgainstTheGroundTruth) {
  const std::string data = test::write_room("folder_inference_room", 7, true, 320, 256);
  const std::string out = test::temp_dir("folder_inference_out");
  FolderInferenceOptions options;
  options.refs = {0, 2};
  std::ostringstream log;
  std::vector<int> finished;
  const auto result = infer_folder(data, kShippedModel, torch::kCPU, out, options, log,
                                   [&](int n, int total, const std::string& line) {
                                     finished.push_back(n);
                                     EXPECT_EQ(total, 2);
                                     EXPECT_NE(line.find("conf>0.8"), std::string::npos) << line;
                                   });
  EXPECT_EQ(result.done, 2);
  EXPECT_EQ(result.skipped, 0);
  EXPECT_EQ(finished, (std::vector<int>{1, 2}));
  EXPECT_NE(log.str().find("model: " + kShippedModel), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("depth planes: "), std::string::npos) << log.str();
  const InferenceFolder written(out);
  const auto pairs = read_pair_file(written.pair_file());
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[1].ref, 2);
  // The rendered room's depth within 10 % on most confident pixels: a real estimate, not a placeholder.
  const auto depth = read_pfm(written.depth_path(2));
  const auto confidence = read_pfm(written.confidence_path(2));
  const MvsCam cam = read_cam_file(written.cam_path(2));
  EXPECT_EQ(cam.depth_num, result.num_depth);
  EXPECT_EQ(depth.sizes(), confidence.sizes());
  const auto gt = sample_depth_at_camera(read_pfm(data + "/depth_gt/00000002.pfm"),
                                         MvsFolder(data).load_view(2).cam.camera, [&] {
                                           Camera c = cam.camera;
                                           c.width = static_cast<int>(depth.size(1));
                                           c.height = static_cast<int>(depth.size(0));
                                           return c;
                                         }());
  DepthMetricsConfig metrics;
  metrics.rel_thresholds = {0.1};
  const auto m = evaluate_depth(depth, gt, confidence >= 0.5, metrics);
  EXPECT_GT(m.evaluated_pixels, gt.numel() / 4);
  EXPECT_GT(m.within_rel[0], 0.8);
}

TEST(FolderInference, RefusesBeforeWritingAnything) {
  const std::string data = test::write_room("folder_inference_refusals", 3, false, 64, 48, 4);
  const std::string out = test::temp_dir("folder_inference_refused") + "/out";
  const auto message = [&](const FolderInferenceOptions& options) {
    std::ostringstream log;
    try {
      infer_folder(data, kShippedModel, torch::kCPU, out, options, log);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  FolderInferenceOptions options;
  options.refs = {9};
  EXPECT_NE(message(options).find("--ref: view 9 is not in " + data + "/pair.txt"), std::string::npos);
  options.refs = {0};
  options.feature_warp = "bent";
  EXPECT_NE(message(options).find("bent"), std::string::npos);
  options.feature_warp = "";
  options.refs = {};
  options.views = 1;
  EXPECT_NE(message(options).find("--views must be at least 2"), std::string::npos);
  options.views = 3;
  options.depth_min = 2;
  options.depth_max = 1;
  EXPECT_NE(message(options).find("impossible depth range: --depth-max 1 <= --depth-min 2"), std::string::npos);
  options.depth_max = 0;
  options.estimator.completion.min_confidence = 1.5;
  EXPECT_NE(message(options).find("--complete-below-confidence must be a confidence in [0,1)"), std::string::npos);
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace umvs
