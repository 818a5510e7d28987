// The RGB-D importer into MVSNet folders (io/import.h import_rgbd): the plain layout, 16-bit
// depth, intrinsics files, distortion and the sources' baseline, on small sequences written here
// (the TUM RGB-D, 7-Scenes and DeepVideoMVS layouts: test_import_sequences.cpp).
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

TEST(ImportRgbd, WritesGroundTruthDepthAndInvertsThePoses) {
  const std::string root = test::temp_dir("import_rgbd");
  fs::create_directories(root + "/data/color");
  fs::create_directories(root + "/data/depth");
  std::ofstream pose(root + "/data/pose.txt");
  for (int i = 1; i <= 3; ++i) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitY()));
    pose << 0.1 * i << " 0 " << -0.05 * i << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w() << "\n";
    write_png(root + "/data/color/" + std::to_string(i) + ".png", torch::full({24, 32, 3}, 50 * i, torch::kUInt8));
    auto raw = torch::full({24, 32}, 5000 * (1 + i), torch::kInt32);  // (1 + i) metres
    raw[0][0] = 0;                                                      // no depth
    write_png_u16(root + "/data/depth/" + std::to_string(i) + ".png", raw);
  }
  pose.close();
  RgbdImportConfig cfg;
  cfg.data_dir = root + "/data";
  cfg.out_dir = root + "/out";
  cfg.intrinsics.K << 481.2, 0, 15.5, 0, -480.0, 11.5, 0, 0, 1;
  const auto summary = import_rgbd(cfg);
  EXPECT_EQ(summary.views, 3);
  MvsFolder folder(cfg.out_dir);
  for (int i = 1; i <= 3; ++i) {
    const auto view = folder.load_view(i);
    EXPECT_DOUBLE_EQ(view.cam.camera.K(1, 1), -480.0);
    EXPECT_NEAR(view.cam.camera.center().x(), 0.1 * i, 1e-9);
    EXPECT_NEAR(view.cam.camera.center().z(), -0.05 * i, 1e-9);
    EXPECT_NEAR(rotation_angle(view.cam.camera.R().transpose(), Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitY()).toRotationMatrix()),
                0.0, 1e-6);
    auto depth = read_pfm(folder.depth_gt_path(i));
    EXPECT_FLOAT_EQ(depth[5][5].item<float>(), 1.0f + i);
    EXPECT_FLOAT_EQ(depth[0][0].item<float>(), 0.0f);
    EXPECT_LE(view.cam.depth_min, 1.0 + i);
    EXPECT_GE(view.cam.depth_max, 1.0 + i);
  }
}

// A 16-bit binary PGM (P5, maxval 65535: big-endian samples), as some RGB-D datasets store depth.
static void write_pgm_u16(const std::string& path, const torch::Tensor& raw) {
  std::ofstream out(path, std::ios::binary);
  out << "P5\n" << raw.size(1) << " " << raw.size(0) << "\n65535\n";
  auto a = raw.accessor<int32_t, 2>();
  for (int64_t y = 0; y < raw.size(0); ++y) {
    for (int64_t x = 0; x < raw.size(1); ++x) out.put(static_cast<char>(a[y][x] >> 8)).put(static_cast<char>(a[y][x] & 0xff));
  }
}

TEST(ImportRgbd, Reads16BitPgmDepthMatchedByStem) {
  const std::string root = test::temp_dir("import_rgbd_pgm");
  fs::create_directories(root + "/data/color");
  fs::create_directories(root + "/data/depth");
  std::ofstream pose(root + "/data/pose.txt");
  for (int i = 1; i <= 3; ++i) {
    pose << 0.1 * i << " 0 0 0 0 0 1\n";
    write_png(root + "/data/color/" + std::to_string(i) + ".png", torch::full({24, 32, 3}, 50 * i, torch::kUInt8));
    auto raw = torch::full({24, 32}, 5000 * (1 + i), torch::kInt32);  // (1 + i) metres: above 8 bits
    raw[3][4] = 5000 * (1 + i) + 777;                                   // a sample whose low byte matters
    raw[0][0] = 0;                                                      // no depth
    write_pgm_u16(root + "/data/depth/" + std::to_string(i) + ".pgm", raw);
  }
  pose.close();
  RgbdImportConfig cfg;
  cfg.data_dir = root + "/data";
  cfg.out_dir = root + "/out";
  cfg.intrinsics.K << 30, 0, 15.5, 0, 30, 11.5, 0, 0, 1;
  EXPECT_EQ(import_rgbd(cfg).views, 3);
  MvsFolder folder(cfg.out_dir);
  for (int i = 1; i <= 3; ++i) {
    auto depth = read_pfm(folder.depth_gt_path(i));
    EXPECT_FLOAT_EQ(depth[5][5].item<float>(), 1.0f + i);
    EXPECT_FLOAT_EQ(depth[3][4].item<float>(), (5000.0f * (1 + i) + 777.0f) / 5000.0f);
    EXPECT_FLOAT_EQ(depth[0][0].item<float>(), 0.0f);
  }
  // No depth image under any known extension: the message names the stem and the extensions tried.
  fs::remove(root + "/data/depth/2.pgm");
  cfg.out_dir = root + "/out2";
  EXPECT_THAT([&] { import_rgbd(cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("depth/2.{png,pgm,tif,tiff}")));
}

TEST(ImportRgbd, BadPoseNamesTheLine) {
  const std::string root = test::temp_dir("import_rgbd_bad");
  fs::create_directories(root + "/color");
  fs::create_directories(root + "/depth");
  std::ofstream(root + "/pose.txt") << "0 0 0 0 0 0 1\n0 0 0 0.5 0.5 0 0.2\n";
  RgbdImportConfig cfg;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.intrinsics.K << 30, 0, 15.5, 0, 30, 11.5, 0, 0, 1;
  EXPECT_THAT([&] { import_rgbd(cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("line 2")));
  // No intrinsics: refused, naming what to give, rather than some data set's camera.
  cfg.intrinsics = {};
  EXPECT_THAT([&] { import_rgbd(cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("--intrinsics FILE or --fx")));
}

TEST(ImportRgbd, IntrinsicsFilesInTheirThreeForms) {
  const std::string root = test::temp_dir("import_intrinsics");
  std::ofstream(root + "/K.txt") << "495.5 0 269.5\n0 495.4 169.2\n0 0 1\n";
  std::ofstream(root + "/line.txt") << "535.4 539.2 320.1 247.6 0.1 -0.2 0.001 0.002\n";
  std::ofstream(root + "/TUM3.yaml") << "%YAML:1.0\nCamera.fx: 535.4\nCamera.fy: 539.2\nCamera.cx: 320.1\nCamera.cy: 247.6\n"
                                        "Camera.k1: 0.0\nCamera.k2: 0.0\n";
  std::ofstream(root + "/bad.txt") << "1 2 3\n";
  const auto K = read_intrinsics_file(root + "/K.txt");
  EXPECT_DOUBLE_EQ(K.K(1, 2), 169.2);
  EXPECT_FALSE(K.distorted());
  const auto line = read_intrinsics_file(root + "/line.txt");
  EXPECT_DOUBLE_EQ(line.K(1, 1), 539.2);
  ASSERT_EQ(line.distortion.size(), 4u);
  EXPECT_DOUBLE_EQ(line.distortion[1], -0.2);
  const auto yaml = read_intrinsics_file(root + "/TUM3.yaml");
  EXPECT_DOUBLE_EQ(yaml.K(0, 2), 320.1);
  EXPECT_FALSE(yaml.distorted());
  EXPECT_THAT([&] { read_intrinsics_file(root + "/bad.txt"); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("bad.txt"), testing::HasSubstr("3 numbers"))));
}

// A checkerboard seen through barrel distortion: after import, straight rows of squares are
// straight again, and the depth (a ramp) is resampled, never blended across its edge.
TEST(ImportRgbd, RemovesDistortionFromColourAndDepth) {
  const std::string root = test::temp_dir("import_distortion");
  fs::create_directories(root + "/color");
  fs::create_directories(root + "/depth");
  const int W = 64, H = 48;
  CameraIntrinsics in;
  in.K << 60, 0, 31.5, 0, 60, 23.5, 0, 0, 1;
  in.distortion = {-0.3, 0.05, 0.0, 0.0};
  // Render the distorted image: for each distorted pixel find its undistorted ray by fixed-point
  // iteration, and colour it by the ray's place on the undistorted pixel grid.
  auto color = torch::zeros({H, W, 3}, torch::kUInt8);
  auto raw = torch::zeros({H, W}, torch::kInt32);
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      const double xd = (u - 31.5) / 60, yd = (v - 23.5) / 60;
      double x = xd, y = yd;
      for (int it = 0; it < 50; ++it) {
        const double r2 = x * x + y * y, radial = 1 - 0.3 * r2 + 0.05 * r2 * r2;
        x = xd / radial;
        y = yd / radial;
      }
      const double uu = 60 * x + 31.5, vv = 60 * y + 23.5;
      const bool white = (static_cast<int>(std::floor(uu / 8)) + static_cast<int>(std::floor(vv / 8))) % 2 == 0;
      for (int c = 0; c < 3; ++c) color[v][u][c] = white ? 255 : 0;
      raw[v][u] = uu < 32 ? 5000 : 10000;  // 1 m left of the undistorted image's middle, 2 m right
    }
  }
  write_png(root + "/color/1.png", color);
  write_png_u16(root + "/depth/1.png", raw);
  write_png(root + "/color/2.png", color);
  write_png_u16(root + "/depth/2.png", raw);
  std::ofstream(root + "/pose.txt") << "0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n";
  RgbdImportConfig cfg;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.intrinsics = in;
  ASSERT_EQ(import_rgbd(cfg).views, 2);
  const auto out = read_image_rgb8(cfg.out_dir + "/images/00000001.png");
  const auto depth = read_pfm(cfg.out_dir + "/depth_gt/00000001.pfm");
  int right = 0, total = 0, mixed = 0;
  for (int v = 4; v < H - 4; ++v) {
    for (int u = 4; u < W - 4; ++u) {
      const int value = out[v][u][0].item<int>();
      const bool white = ((u / 8) + (v / 8)) % 2 == 0;
      if (u % 8 != 0 && u % 8 != 7 && v % 8 != 0 && v % 8 != 7) {  // away from square edges
        ++total;
        right += white ? value > 200 : value < 55;
      }
      const float z = depth[v][u].item<float>();
      mixed += (z != 1.0f && z != 2.0f && z != 0.0f);
      if (u < 30 || u > 33) EXPECT_FLOAT_EQ(z, u < 32 ? 1.0f : 2.0f) << u << "," << v;
    }
  }
  EXPECT_GT(static_cast<double>(right) / total, 0.97) << right << " of " << total;
  EXPECT_EQ(mixed, 0);
}

TEST(ImportRgbd, SourcesAtTheWantedBaselineRankFirst) {
  const std::string root = test::temp_dir("import_baseline");
  fs::create_directories(root + "/color");
  fs::create_directories(root + "/depth");
  std::ofstream pose(root + "/pose.txt");
  for (int i = 1; i <= 8; ++i) {
    pose << 0.02 * i << " 0 0 0 0 0 1\n";  // 2 cm steps, a wall 0.5 m away
    write_png(root + "/color/" + std::to_string(i) + ".png", torch::full({24, 32, 3}, 50, torch::kUInt8));
    write_png_u16(root + "/depth/" + std::to_string(i) + ".png", torch::full({24, 32}, 2500, torch::kInt32));
  }
  pose.close();
  RgbdImportConfig cfg;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  cfg.intrinsics.K << 30, 0, 15.5, 0, 30, 11.5, 0, 0, 1;
  cfg.num_sources = 3;
  import_rgbd(cfg);
  const auto near = MvsFolder(cfg.out_dir).pair_of(1).sources;
  // Without a baseline: MVSNet's score, which peaks at 5 degrees (4-6 cm at 0.5 m).
  EXPECT_TRUE(near.front() == 3 || near.front() == 4) << near.front();
  cfg.out_dir = root + "/out_baseline";
  cfg.min_baseline = 0.09;
  cfg.max_baseline = 0.13;
  import_rgbd(cfg);
  const auto far = MvsFolder(cfg.out_dir).pair_of(1).sources;
  ASSERT_EQ(far.size(), 3u);
  for (int k = 0; k < 2; ++k) EXPECT_TRUE(far[k] == 6 || far[k] == 7) << far[k];  // 10 and 12 cm away
  // A fixed range replaces the sensor's.
  cfg.out_dir = root + "/out_range";
  cfg.depth_near = 0.5;
  cfg.depth_far = 8.0;
  import_rgbd(cfg);
  const auto cam = MvsFolder(cfg.out_dir).load_view(3).cam;
  EXPECT_DOUBLE_EQ(cam.depth_min, 0.5);
  EXPECT_DOUBLE_EQ(cam.depth_max, 8.0);
  // ... and with it the sensor's depth reaches depth_gt/ alone: other depth images, the same folder
  // otherwise (a folder a model may train on without labels).
  for (int i = 1; i <= 8; ++i) {
    write_png_u16(root + "/depth/" + std::to_string(i) + ".png", torch::full({24, 32}, 2500 * i, torch::kInt32));
  }
  cfg.out_dir = root + "/out_range_other_depth";
  import_rgbd(cfg);
  EXPECT_EQ(read_file_bytes(root + "/out_range/pair.txt"), read_file_bytes(cfg.out_dir + "/pair.txt"));
  EXPECT_EQ(read_file_bytes(root + "/out_range/cams/00000003_cam.txt"), read_file_bytes(cfg.out_dir + "/cams/00000003_cam.txt"));
  EXPECT_NE(read_file_bytes(root + "/out_range/depth_gt/00000003.pfm"), read_file_bytes(cfg.out_dir + "/depth_gt/00000003.pfm"));
}

}  // namespace
}  // namespace umvs
