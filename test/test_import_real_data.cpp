// Imports of the real data sets of ../shared/data (templeRing, the living room, the HoloLens
// kitchen, TUM's cabinet, 7-Scenes' red kitchen): cameras, ranges and pairs, and sensor depth
// that other views confirm. Skipped where the data is missing.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <filesystem>
#include <string>
#include <utility>

#include "test_util.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/import.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {
namespace {

TEST(ImportRealData, TempleRing) {
  UMVS_REQUIRE_SHARED("templeRing", data);
  const std::string out = test::temp_dir("import_temple");
  MiddleburyImportConfig cfg;
  cfg.data_dir = data;
  cfg.out_dir = out;
  const auto summary = import_middlebury(cfg);
  EXPECT_EQ(summary.views, 19);
  EXPECT_EQ(summary.skipped, 47 - 19);
  MvsFolder folder(out);
  const auto view = folder.load_view(16);
  EXPECT_EQ(view.image.size(1), 640);
  EXPECT_NEAR(view.cam.camera.K(0, 0), 1520.4, 1e-9);
  // The parity case of MVSNet_pytorch used 0.488..0.652 m for this view: the box range is inside it.
  EXPECT_GT(view.cam.depth_min, 0.4);
  EXPECT_LT(view.cam.depth_max, 0.7);
  const auto& p = folder.pair_of(16);
  ASSERT_GE(p.sources.size(), 2u);
  EXPECT_TRUE(p.sources[0] == 15 || p.sources[0] == 17) << p.sources[0];
}

TEST(ImportRealData, LivingRoomDepthIsConsistentAcrossViews) {
  UMVS_REQUIRE_SHARED("livingroom", data);
  const std::string out = test::temp_dir("import_living");
  RgbdImportConfig cfg;
  cfg.data_dir = data;
  cfg.out_dir = out;
  cfg.intrinsics = test::living_room_intrinsics();
  EXPECT_EQ(import_rgbd(cfg).views, 5);
  MvsFolder folder(out);
  // View 3 against view 1 (they overlap well): the ground-truth depths agree where both see the
  // scene; a wrong fy sign or an uninverted pose would make almost nothing agree.
  auto load = [&](int id) {
    auto v = folder.load_view(id);
    return std::make_pair(read_pfm(folder.depth_gt_path(id)), v.cam.camera);
  };
  auto [d3, c3] = load(3);
  auto [d1, c1] = load(1);
  FusionConfig fc;
  fc.max_relative_depth = 0.02;
  fc.max_reprojection_px = 2.0;
  auto check = check_consistency(d3, d3 > 0, c3, d1, d1 > 0, c1, fc);
  const double agree = check.agree.to(torch::kFloat64).mean().item<double>();
  EXPECT_GT(agree, 0.2) << "share of view 3 confirmed by view 1";
}

// Two views of an imported real RGB-D set: the share of view a's sensor depth that view b's
// confirms (fusion's round trip at 2 px and 3 %). A wrong pose convention, an uninverted pose, a
// wrong depth scale or the wrong frame association make almost nothing agree.
double sensor_depth_agreement(const std::string& folder, int a, int b) {
  MvsFolder f(folder);
  const auto da = read_pfm(f.depth_gt_path(a)), db = read_pfm(f.depth_gt_path(b));
  FusionConfig fc;
  fc.max_relative_depth = 0.03;
  fc.max_reprojection_px = 2.0;
  const auto check = check_consistency(da, da > 0, f.load_view(a).cam.camera, db, db > 0, f.load_view(b).cam.camera, fc);
  return check.agree.to(torch::kFloat64).sum().item<double>() / (da > 0).sum().item<double>();
}

TEST(ImportRealData, HoloLensKitchen) {
  UMVS_REQUIRE_SHARED("hololens_kitchen", data);
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kDvmvs;
  cfg.data_dir = data + "/raw/hololens-dataset/000";
  cfg.out_dir = test::temp_dir("import_hololens");
  cfg.count = 4;
  EXPECT_EQ(import_rgbd(cfg).views, 4);
  const auto view = MvsFolder(cfg.out_dir).load_view(3);  // image 00003 is row 0 of poses.txt
  EXPECT_NEAR(view.cam.camera.K(0, 0), 495.568, 1e-3);
  EXPECT_GT(sensor_depth_agreement(cfg.out_dir, 3, 6), 0.5);
}

TEST(ImportRealData, TumCabinetKeyframes) {
  UMVS_REQUIRE_SHARED("tum_fr3_cabinet_kf", data);
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kTum;
  cfg.data_dir = data + "/raw/data";
  cfg.out_dir = test::temp_dir("import_tum_cabinet");
  cfg.tum_pose_file = "truth_cam_poses.txt";
  cfg.tum_association = "index";  // the lists are numbered 0..57, the poses carry the camera's times
  cfg.intrinsics = read_intrinsics_file(cfg.data_dir + "/TUM3.yaml");
  cfg.first = 2;
  cfg.count = 3;
  EXPECT_EQ(import_rgbd(cfg).views, 3);
  EXPECT_GT(sensor_depth_agreement(cfg.out_dir, 3, 4), 0.5);  // a pair PROVENANCE lists as clean
}

TEST(ImportRealData, SevenScenesRedKitchen) {
  UMVS_REQUIRE_SHARED("sevenscenes_redkitchen", data);
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kSevenScenes;
  cfg.data_dir = data + "/raw/data";
  cfg.out_dir = test::temp_dir("import_7scenes_real");
  cfg.count = 4;
  EXPECT_EQ(import_rgbd(cfg).views, 4);  // poses with R^T R - I up to 1e-4 are repaired, not refused
  const auto view = MvsFolder(cfg.out_dir).load_view(12);
  EXPECT_LT(orthonormality_error(view.cam.camera.R()), 1e-9);
  EXPECT_GT(sensor_depth_agreement(cfg.out_dir, 0, 12), 0.5);
}

}  // namespace
}  // namespace umvs
