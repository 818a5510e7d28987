// The datasets' own layouts through the RGB-D importer (io/import.h import_rgbd): TUM RGB-D
// (associated by timestamp or by row), 7-Scenes (its intrinsics, rounded poses) and DeepVideoMVS,
// on small sequences written here.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_util.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/import.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;

// Camera-to-world pose of frame i of the small sequences below: 10 cm steps along x, turning
// about y.
Eigen::Matrix4d sequence_pose(int i) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(0.1 * i, 0.0, 0.0);
  return T;
}
torch::Tensor frame_color(int i) { return torch::full({24, 32, 3}, 20 + 30 * i, torch::kUInt8); }
torch::Tensor frame_depth_mm(int i) { return torch::full({24, 32}, 1000 * (2 + i), torch::kInt32); }

// Every frame of `folder` has the image, the inverted pose and the depth (2 + i metres) of frame i.
void expect_sequence(const std::string& folder, const std::vector<int>& ids, const std::vector<int>& frames) {
  MvsFolder out(folder);
  ASSERT_EQ(out.pairs().size(), ids.size());
  for (size_t k = 0; k < ids.size(); ++k) {
    const auto view = out.load_view(ids[k]);
    EXPECT_EQ(view.image[0][0][0].item<int>(), 20 + 30 * frames[k]) << "view " << ids[k];
    EXPECT_TRUE(view.cam.camera.T_world_cam().isApprox(sequence_pose(frames[k]), 1e-6)) << "view " << ids[k];
    EXPECT_FLOAT_EQ(read_pfm(out.depth_gt_path(ids[k]))[5][5].item<float>(), 2.0f + frames[k]) << "view " << ids[k];
  }
}

TEST(ImportTum, AssociatesByNearestTimestampWithinTheTolerance) {
  const std::string root = test::temp_dir("import_tum");
  fs::create_directories(root + "/rgb");
  fs::create_directories(root + "/depth");
  std::ofstream rgb(root + "/rgb.txt"), depth(root + "/depth.txt"), truth(root + "/groundtruth.txt");
  rgb << "# color images\n# timestamp filename\n";
  depth << "# depth maps\n";
  truth << "# ground truth trajectory\n" << std::setprecision(17);
  for (int i = 0; i < 4; ++i) {
    const double t = 1341841278.0 + 0.5 * i;
    const std::string stamp = std::to_string(t);
    write_png(root + "/rgb/" + stamp + ".png", frame_color(i));
    write_png_u16(root + "/depth/" + stamp + ".png", frame_depth_mm(i) * 5);  // TUM: value / 5000 = m
    rgb << std::setprecision(17) << t << " rgb/" << stamp << ".png\n";
    depth << std::setprecision(17) << t + 0.011 << " depth/" << stamp << ".png\n";
    // Motion capture at 100 Hz: the pose 4 ms from the image, another 6 ms away on the other side.
    for (double dt : {-0.006, 0.004}) {
      const Eigen::Quaterniond q(Eigen::Matrix3d(sequence_pose(i).topLeftCorner<3, 3>()));
      const Eigen::Vector3d p = dt < 0 ? Eigen::Vector3d(9, 9, 9) : Eigen::Vector3d(sequence_pose(i).topRightCorner<3, 1>());
      truth << t + dt << " " << p.x() << " " << p.y() << " " << p.z() << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w() << "\n";
    }
  }
  rgb << 1341841300.0 << " rgb/none.png\n";  // no depth or pose near it: left out
  rgb.close();
  depth.close();
  truth.close();
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kTum;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.intrinsics.K << 30, 0, 15.5, 0, 30, 11.5, 0, 0, 1;
  EXPECT_EQ(import_rgbd(cfg).views, 4);
  expect_sequence(cfg.out_dir, {0, 1, 2, 3}, {0, 1, 2, 3});
  // A tolerance below the depth images' 11 ms offset finds no frame, and says which clock to suspect.
  cfg.tum_max_dt = 0.005;
  cfg.out_dir = root + "/out2";
  EXPECT_THAT([&] { import_rgbd(cfg); }, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("--associate index")));
}

TEST(ImportTum, AssociatesByRowWhenTimestampsDiffer) {
  // The shape of TUM keyframe exports: lists numbered 0..N-1, poses with the camera's real times.
  const std::string root = test::temp_dir("import_tum_rows");
  fs::create_directories(root + "/img");
  std::ofstream rgb(root + "/rgb.txt"), depth(root + "/depth.txt"), truth(root + "/truth.txt");
  for (int i = 0; i < 3; ++i) {
    write_png(root + "/img/" + std::to_string(i) + "_rgb.png", frame_color(i));
    write_png_u16(root + "/img/" + std::to_string(i) + "_depth.png", frame_depth_mm(i) * 5);
    rgb << i << " img/" << i << "_rgb.png\n";
    depth << i << " img/" << i << "_depth.png\n";
    const Eigen::Quaterniond q(Eigen::Matrix3d(sequence_pose(i).topLeftCorner<3, 3>()));
    truth << std::setprecision(17) << 1341841278.8 + i << "\t" << 0.1 * i << "\t0\t0\t" << q.x() << "\t" << q.y() << "\t" << q.z() << "\t"
          << q.w() << "\t\n";
  }
  rgb.close();
  depth.close();
  truth.close();
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kTum;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.tum_pose_file = "truth.txt";
  cfg.intrinsics.K << 30, 0, 15.5, 0, 30, 11.5, 0, 0, 1;
  EXPECT_THROW(import_rgbd(cfg), std::runtime_error);  // by timestamp nothing matches
  cfg.tum_association = "index";
  EXPECT_EQ(import_rgbd(cfg).views, 3);
  expect_sequence(cfg.out_dir, {0, 1, 2}, {0, 1, 2});
}

TEST(ImportSevenScenes, ReadsItsOwnIntrinsicsRepairsRoundedPosesAndDropsNoDepth) {
  const std::string root = test::temp_dir("import_7scenes");
  std::ofstream(root + "/camera-intrinsics.txt") << "3.0e+01 0 1.55e+01\n0 3.0e+01 1.15e+01\n0 0 1\n";
  for (int i = 0; i < 3; ++i) {
    char stem[64];
    std::snprintf(stem, sizeof(stem), "%s/frame-%06d", root.c_str(), 4 * i);
    write_png(std::string(stem) + ".color.png", frame_color(i));
    auto raw = frame_depth_mm(i);
    raw[0][0] = 65535;  // Kinect's "no measurement"
    write_png_u16(std::string(stem) + ".depth.png", raw);
    std::ofstream pose(std::string(stem) + ".pose.txt");
    pose << std::setprecision(5);  // as few digits as 7-Scenes: R^T R - I ~ 1e-5
    for (int r = 0; r < 4; ++r) pose << sequence_pose(i)(r, 0) << " " << sequence_pose(i)(r, 1) << " " << sequence_pose(i)(r, 2) << " " << sequence_pose(i)(r, 3) << "\n";
  }
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kSevenScenes;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  EXPECT_EQ(import_rgbd(cfg).views, 3);
  MvsFolder out(cfg.out_dir);
  for (int i = 0; i < 3; ++i) {
    const auto view = out.load_view(4 * i);
    EXPECT_DOUBLE_EQ(view.cam.camera.K(0, 2), 15.5);
    EXPECT_LT(orthonormality_error(view.cam.camera.R()), 1e-9);
    EXPECT_LT(rotation_angle(view.cam.camera.R().transpose(), sequence_pose(i).topLeftCorner<3, 3>()), 1e-4);
    const auto depth = read_pfm(out.depth_gt_path(4 * i));
    EXPECT_FLOAT_EQ(depth[0][0].item<float>(), 0.0f);
    EXPECT_FLOAT_EQ(depth[5][5].item<float>(), 2.0f + i);  // millimetres
  }
}

TEST(ImportDvmvs, RowKIsTheKthImageAndFramesCanBeSelected) {
  const std::string root = test::temp_dir("import_dvmvs");
  fs::create_directories(root + "/images");
  fs::create_directories(root + "/depth");
  std::ofstream(root + "/K.txt") << "30 0 15.5\n0 30 11.5\n0 0 1\n";
  std::ofstream poses(root + "/poses.txt");
  poses << std::setprecision(17);
  for (int i = 0; i < 5; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%05d.png", 3 + i);  // numbered from 3, as the HoloLens sample
    write_png(root + "/images/" + name, frame_color(i));
    write_png_u16(root + "/depth/" + name, frame_depth_mm(i));
    for (int k = 0; k < 16; ++k) poses << sequence_pose(i)(k / 4, k % 4) << (k < 15 ? " " : "\n");
  }
  poses.close();
  RgbdImportConfig cfg;
  cfg.layout = RgbdLayout::kDvmvs;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.first = 1;
  cfg.every = 2;
  EXPECT_EQ(import_rgbd(cfg).views, 2);  // frames 1 and 3
  expect_sequence(cfg.out_dir, {4, 6}, {1, 3});
  cfg.first = 9;
  cfg.out_dir = root + "/out2";
  EXPECT_THAT([&] { import_rgbd(cfg); }, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("no frame left")));
}

}  // namespace
}  // namespace umvs
