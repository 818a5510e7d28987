// PCL at the edge: .pcd/.ply files that PCL reads, the PCL point type, and the cloud filters
// (io/cloud_file.h, io/pcl_cloud.h, io/cloud_filter.h).
#ifdef UMVS_HAVE_PCL
#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <cmath>
#include <filesystem>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/cloud_filter.h"
#include "unsup_mvs/io/pcl_cloud.h"
#include "unsup_mvs/io/ply.h"

namespace umvs {
namespace {

using test::file_bytes;

// A 20 x 20 grid on z = 0 (spacing 1 cm, offset half a cell so that 2 cm voxels split it evenly),
// each point with its own colour, confidence and view count.
PointCloud grid_patch() {
  PointCloud c;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      c.points.emplace_back(0.005f + 0.01f * i, 0.005f + 0.01f * j, 0.0f);
      c.colors.push_back({static_cast<uint8_t>(10 * i), static_cast<uint8_t>(10 * j), 77});
      c.confidence.push_back(0.5f + 0.02f * i);
      c.num_views.push_back(static_cast<uint8_t>(2 + j % 5));
    }
  }
  return c;
}

TEST(CloudFile, PcdAndPlyOpenWithPcl) {
  const auto dir = test::temp_dir("cloud_file");
  const PointCloud c = grid_patch();

  write_cloud(dir + "/c.pcd", c);
  EXPECT_NE(file_bytes(dir + "/c.pcd").find("DATA binary_compressed"), std::string::npos);
  pcl::PCLPointCloud2 blob;
  ASSERT_EQ(pcl::io::loadPCDFile(dir + "/c.pcd", blob), 0);
  std::vector<std::string> fields;
  for (const auto& f : blob.fields) fields.push_back(f.name);
  EXPECT_EQ(fields, (std::vector<std::string>{"x", "y", "z", "rgb", "confidence", "views"}));
  pcl::PointCloud<FusedPoint> pcd;
  ASSERT_EQ(pcl::io::loadPCDFile(dir + "/c.pcd", pcd), 0);
  ASSERT_EQ(pcd.size(), c.size());
  for (size_t i = 0; i < c.size(); ++i) {
    ASSERT_EQ(pcd[i].getVector3fMap(), c.points[i]) << i;
    ASSERT_EQ(pcd[i].r, c.colors[i][0]);
    ASSERT_EQ(pcd[i].g, c.colors[i][1]);
    ASSERT_EQ(pcd[i].b, c.colors[i][2]);
    ASSERT_EQ(pcd[i].confidence, c.confidence[i]);
    ASSERT_EQ(pcd[i].views, c.num_views[i]);
  }
  // ... and our reader gets everything back.
  const PointCloud r = read_cloud(dir + "/c.pcd");
  EXPECT_EQ(r.points, c.points);
  EXPECT_EQ(r.colors, c.colors);
  EXPECT_EQ(r.confidence, c.confidence);
  EXPECT_EQ(r.num_views, c.num_views);

  // Our PLY opens in PCL with its colours.
  write_cloud(dir + "/c.ply", c);
  pcl::PointCloud<pcl::PointXYZRGB> ply;
  ASSERT_EQ(pcl::io::loadPLYFile(dir + "/c.ply", ply), 0);
  ASSERT_EQ(ply.size(), c.size());
  for (size_t i = 0; i < c.size(); ++i) {
    ASSERT_EQ(ply[i].getVector3fMap(), c.points[i]) << i;
    ASSERT_EQ(ply[i].r, c.colors[i][0]);
    ASSERT_EQ(ply[i].g, c.colors[i][1]);
    ASSERT_EQ(ply[i].b, c.colors[i][2]);
  }
  // A PLY that PCL wrote reads back with read_cloud (positions and colours: what PLY carries).
  ASSERT_EQ(pcl::io::savePLYFileBinary(dir + "/pcl.ply", ply), 0);
  const PointCloud p = read_cloud(dir + "/pcl.ply");
  EXPECT_EQ(p.points, c.points);
  EXPECT_EQ(p.colors, c.colors);
}

TEST(CloudFile, WrongExtensionOrLinkRefusedAndExistingFilesKept) {
  const auto dir = test::temp_dir("cloud_file_refused");
  const PointCloud c = grid_patch();
  PointCloud other;
  other.points.emplace_back(9, 9, 9);
  write_cloud(dir + "/keep.pcd", c);
  const std::string before = file_bytes(dir + "/keep.pcd");

  EXPECT_EQ(cloud_file_format(dir + "/a.PCD"), CloudFileFormat::kPcd);
  for (const std::string name : {"cloud.xyz", "cloud", "cloud.pcd.bak"}) {
    try {
      write_cloud(dir + "/" + name, other);
      ADD_FAILURE() << name << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("unknown point-cloud extension '" +
                                           std::filesystem::path(name).extension().string() + "'"),
                std::string::npos)
          << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(dir + "/" + name));
    EXPECT_THROW(read_cloud(dir + "/" + name), std::invalid_argument);
  }
  // A planted link is refused, not followed: the file it points to stays as it was.
  std::filesystem::create_symlink(dir + "/keep.pcd", dir + "/link.pcd");
  EXPECT_THROW(write_cloud(dir + "/link.pcd", other), std::runtime_error);
  // An unwritable target (its folder is a file) fails with the path named.
  std::ofstream(dir + "/blocker") << "x";
  try {
    write_cloud(dir + "/blocker/out.pcd", other);
    ADD_FAILURE() << "wrote into a file";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir + "/blocker"), std::string::npos) << e.what();
  }
  EXPECT_EQ(file_bytes(dir + "/keep.pcd"), before);
  // Files that are not what their extension says get an error naming them.
  std::ofstream(dir + "/bad.pcd") << "not a point cloud\n";
  try {
    read_cloud(dir + "/bad.pcd");
    ADD_FAILURE() << "read garbage";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir + "/bad.pcd"), std::string::npos) << e.what();
  }
}

TEST(CloudFilter, OutlierRemovalDropsExactlyThePlantedOutliers) {
  PointCloud c = grid_patch();
  const size_t dense = c.size();
  // Five far points, far from each other too.
  for (int k = 0; k < 5; ++k) {
    c.points.emplace_back(1.0f + k, -1.0f, 0.5f * k);
    c.colors.push_back({255, 0, 0});
    c.confidence.push_back(0.9f);
    c.num_views.push_back(9);
  }
  CloudFilterConfig sor;
  sor.sor_mean_k = 20;
  sor.sor_std_mul = 2.0;
  std::vector<CloudFilterStep> steps;
  const PointCloud s = filter_cloud(c, sor, &steps);
  ASSERT_EQ(s.size(), dense);
  ASSERT_EQ(steps.size(), 1u);
  EXPECT_EQ(steps[0].name, "statistical");
  EXPECT_EQ(steps[0].points_before, dense + 5);
  EXPECT_EQ(steps[0].points_after, dense);
  // The survivors are the patch, in order, with their attributes untouched.
  EXPECT_EQ(s.points, std::vector<Eigen::Vector3f>(c.points.begin(), c.points.begin() + dense));
  EXPECT_EQ(s.colors, (std::vector<std::array<uint8_t, 3>>(c.colors.begin(), c.colors.begin() + dense)));
  EXPECT_EQ(s.confidence, std::vector<float>(c.confidence.begin(), c.confidence.begin() + dense));
  EXPECT_EQ(s.num_views, std::vector<uint8_t>(c.num_views.begin(), c.num_views.begin() + dense));

  CloudFilterConfig radius;
  radius.radius = 0.05;
  radius.radius_min_neighbors = 3;
  const PointCloud r = filter_cloud(c, radius);
  EXPECT_EQ(r.points, s.points);

  // Nothing enabled: the cloud as it was.
  EXPECT_EQ(filter_cloud(c, CloudFilterConfig{}).points, c.points);
}

TEST(CloudFilter, VoxelGridAveragesEachCube) {
  const PointCloud c = grid_patch();
  CloudFilterConfig cfg;
  cfg.voxel_leaf = 0.02;  // 2 x 2 grid points per cube: 10 x 10 cubes
  const PointCloud v = filter_cloud(c, cfg);
  ASSERT_EQ(v.size(), 100u);
  ASSERT_EQ(v.colors.size(), 100u);
  ASSERT_EQ(v.confidence.size(), 100u);
  ASSERT_EQ(v.num_views.size(), 100u);
  for (size_t k = 0; k < v.size(); ++k) {
    // The centroid of points i, i+1 (j, j+1) with i, j even: x = 0.01 + 0.02 * i / 2.
    const int i = static_cast<int>(std::lround((v.points[k].x() - 0.01f) / 0.01f));
    const int j = static_cast<int>(std::lround((v.points[k].y() - 0.01f) / 0.01f));
    ASSERT_NEAR(v.points[k].x(), 0.01f + 0.01f * i, 1e-5);
    ASSERT_NEAR(v.points[k].y(), 0.01f + 0.01f * j, 1e-5);
    ASSERT_EQ(i % 2, 0);
    ASSERT_EQ(j % 2, 0);
    // Mean colour, confidence and views of the four.
    EXPECT_NEAR(v.colors[k][0], 10 * i + 5, 1);
    EXPECT_NEAR(v.colors[k][1], 10 * j + 5, 1);
    EXPECT_EQ(v.colors[k][2], 77);
    EXPECT_NEAR(v.confidence[k], 0.5f + 0.02f * i + 0.01f, 1e-5);
    EXPECT_EQ(v.num_views[k], std::lround((2 + j % 5 + 2 + (j + 1) % 5) / 2.0));
  }
}

TEST(CloudFilter, BadSettingsAreNamed) {
  auto refused = [](CloudFilterConfig c, const std::string& name) {
    try {
      c.validate();
      ADD_FAILURE() << name << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  };
  CloudFilterConfig c;
  c.sor_mean_k = -1;
  refused(c, "sor_mean_k");
  c = {};
  c.sor_mean_k = 10;
  c.sor_std_mul = 0;
  refused(c, "sor_std_mul");
  c = {};
  c.radius = 0.1;
  c.radius_min_neighbors = 0;
  refused(c, "radius_min_neighbors");
  c = {};
  c.voxel_leaf = -0.01;
  refused(c, "voxel_leaf");
}

}  // namespace
}  // namespace umvs
#endif  // UMVS_HAVE_PCL
