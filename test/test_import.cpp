// Importers of real data sets (Middlebury multi-view, RGB-D sequences) into MVSNet folders.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <filesystem>
#include <fstream>
#include <iomanip>

#include "test_util.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/import.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;

// World-to-camera rotation of a camera at `eye` looking at `target` (z up in the world).
Eigen::Matrix3d look_at_rotation(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  return Camera::look_at(eye, target, Eigen::Matrix3d::Identity(), 1, 1).R();
}

TEST(ImportMiddlebury, ParsesTheBoundingBoxOfTheReadme) {
  Eigen::Vector3d lo, hi;
  ASSERT_TRUE(parse_middlebury_bbox("The (tight) bounding box for the templeRing model is\n(-0.023121 -0.038009 -0.091940)\n"
                                    "(0.078626 0.121636 -0.017395)\n",
                                    &lo, &hi));
  EXPECT_DOUBLE_EQ(lo.x(), -0.023121);
  EXPECT_DOUBLE_EQ(hi.y(), 0.121636);
  EXPECT_DOUBLE_EQ(lo.z(), -0.091940);
  EXPECT_FALSE(parse_middlebury_bbox("no box here (1 2)", &lo, &hi));
}

// A ring of 6 cameras around a 0.2 m box, written in the Middlebury layout.
std::string write_fake_middlebury(const std::string& dir) {
  std::ofstream par(dir + "/fake_par.txt");
  par << "7\n" << std::setprecision(17);
  for (int i = 0; i < 7; ++i) {
    const double a = 2 * M_PI * i / 12;  // 30 degrees apart
    const Eigen::Vector3d eye(0.8 * std::cos(a), 0.8 * std::sin(a), 0.3);
    const Eigen::Matrix3d R = look_at_rotation(eye, Eigen::Vector3d::Zero());
    const Eigen::Vector3d t = -R * eye;
    char name[32];
    std::snprintf(name, sizeof(name), "fake%04d.png", 20 + i);
    par << name << " 500 0 31.5 0 500 23.5 0 0 1";
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) par << " " << R(r, c);
    par << " " << t.x() << " " << t.y() << " " << t.z() << "\n";
    if (i != 6) write_png(dir + "/" + name, torch::full({48, 64, 3}, 10 * i, torch::kUInt8));  // the last has no image
  }
  std::ofstream(dir + "/README.txt") << "bounding box\n(-0.1 -0.1 -0.1)\n(0.1 0.1 0.1)\n";
  return dir;
}

TEST(ImportMiddlebury, WritesCamerasRangesAndPairs) {
  const std::string root = test::temp_dir("import_mb");
  const std::string data = root + "/data", out = root + "/out";
  fs::create_directories(data);
  write_fake_middlebury(data);
  MiddleburyImportConfig cfg;
  cfg.data_dir = data;
  cfg.out_dir = out;
  cfg.num_sources = 3;
  const auto summary = import_middlebury(cfg);
  EXPECT_EQ(summary.views, 6);
  EXPECT_EQ(summary.skipped, 1);
  MvsFolder folder(out);
  ASSERT_EQ(folder.pairs().size(), 6u);
  EXPECT_EQ(folder.pairs()[0].ref, 20);
  for (int id = 20; id < 26; ++id) {
    const auto view = folder.load_view(id);
    EXPECT_EQ(view.image[0][0][0].item<int>(), 10 * (id - 20));
    EXPECT_DOUBLE_EQ(view.cam.camera.K(0, 0), 500);
    // Every box corner lies inside the depth range, and the range is not much wider than the box.
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d corner((k & 1) ? 0.1 : -0.1, (k & 2) ? 0.1 : -0.1, (k & 4) ? 0.1 : -0.1);
      const double z = (view.cam.camera.R() * corner + view.cam.camera.t()).z();
      EXPECT_GT(z, view.cam.depth_min);
      EXPECT_LT(z, view.cam.depth_max);
    }
    EXPECT_LT(view.cam.depth_max - view.cam.depth_min, 0.35 * 1.2 + 1e-6);
    EXPECT_EQ(view.cam.depth_num, 192);
    // Neighbours on the ring (30 degrees) come before views 60+ degrees away.
    const auto& p = folder.pair_of(id);
    ASSERT_EQ(p.sources.size(), 3u);
    EXPECT_EQ(std::abs(p.sources[0] - id), 1) << "view " << id;
  }
  cfg.data_dir = data + "/missing";
  EXPECT_THROW(import_middlebury(cfg), std::runtime_error);
}

TEST(ImportMiddlebury, MalformedCalibrationNamesTheFile) {
  const std::string root = test::temp_dir("import_mb_bad");
  std::ofstream(root + "/x_par.txt") << "1\nx0001.png 500 0 31 0 500 23 0 0 1 1 0 0 0 1 0 0 0 nan 0 0 1\n";
  std::ofstream(root + "/README.txt") << "(0 0 0)\n(1 1 1)\n";
  MiddleburyImportConfig cfg;
  cfg.data_dir = root;
  cfg.out_dir = root + "/out";
  EXPECT_THAT([&] { import_middlebury(cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("x_par.txt")));
  EXPECT_FALSE(fs::exists(root + "/out/pair.txt"));
}

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
  cfg.cx = 15.5;
  cfg.cy = 11.5;
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
  EXPECT_THAT([&] { import_rgbd(cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("line 2")));
}

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

}  // namespace
}  // namespace umvs
