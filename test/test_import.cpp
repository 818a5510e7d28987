// Importers of real data sets into MVSNet folders: Middlebury multi-view (io/import.h
// import_middlebury). RGB-D sequences: test_import_rgbd.cpp; the real data sets of ../shared/data:
// test_import_real_data.cpp.
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

#include "test_util.h"
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

}  // namespace
}  // namespace umvs
