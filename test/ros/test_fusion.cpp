// rostest for the fusion node: depth estimates of a plane seen by cameras moving along x become a
// PointCloud2 on the plane (frame, stamp, PCL fields checked); save_cloud writes a PLY and a PCD
// that PCL opens, with the same points, refuses other extensions and never replaces a good file
// with nothing; reset clears; an object that leaves is removed from the cloud and the grid (kept, as
// a costmap keeps it, from the latched whole and the changed windows of occupancy_grid_updates)
// while the plane behind it keeps its points; bad estimates (another world frame, NaN pose, wrong depth encoding)
// are logged and skipped.
#include <map_msgs/OccupancyGridUpdate.h>
#include <nav_msgs/OccupancyGrid.h>
#include <octomap/OcTree.h>
#include <pcl/io/pcd_io.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <torch/torch.h>

#include <boost/make_shared.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>
#include <tuple>

#include "reconfigure_client.h"
#include "rostest_util.h"
#include "test_messages.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/ResetFusion.h"
#include "unsup_mvs/SaveCloud.h"
#include "unsup_mvs/io/pcl_cloud.h"
#include "unsup_mvs/io/ply.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace {

using umvs_test::wait_for;
using umvs_test::kPlaneZ;
using umvs_test::reconfigure;
using umvs_test::Request;

// Red, so that the cloud's colour can be checked.
unsup_mvs::DepthEstimate make_estimate(uint32_t id, double x) {
  return umvs_test::plane_estimate(id, x, "cam", {200, 0, 0});
}

// The grid as costmap_2d's static layer keeps it: the latched whole, then each changed window
// written into it (callbacks run in wait_for's spinOnce, on this thread).
struct GridListener {
  explicit GridListener(ros::NodeHandle& nh) {
    whole = nh.subscribe<nav_msgs::OccupancyGrid>("/occupancy_grid", 5, [this](const nav_msgs::OccupancyGridConstPtr& m) {
      grid = boost::make_shared<nav_msgs::OccupancyGrid>(*m);
      ++wholes;
    });
    windows = nh.subscribe<map_msgs::OccupancyGridUpdate>(
        "/occupancy_grid_updates", 50, [this](const map_msgs::OccupancyGridUpdateConstPtr& u) {
          // Before a whole grid, or older than it (published before it, arriving after): in it already.
          if (!grid || u->header.stamp < grid->header.stamp) return;
          ++updates;
          EXPECT_LE(u->x + u->width, grid->info.width);
          EXPECT_LE(u->y + u->height, grid->info.height);
          EXPECT_EQ(u->data.size(), static_cast<size_t>(u->width) * u->height);
          for (uint32_t j = 0; j < u->height; ++j) {
            std::copy_n(u->data.begin() + j * u->width, u->width,
                        grid->data.begin() + (u->y + j) * grid->info.width + u->x);
          }
          grid->header.stamp = u->header.stamp;
        });
  }
  boost::shared_ptr<nav_msgs::OccupancyGrid> grid;
  int wholes = 0, updates = 0;
  ros::Subscriber whole, windows;
};

class FusionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    estimate_pub_ = nh_.advertise<unsup_mvs::DepthEstimate>("/depth_estimate", 20);
    cloud_sub_ = nh_.subscribe("/cloud", 5, &FusionTest::onCloud, this);
    increment_sub_ = nh_.subscribe("/cloud_increment", 20, &FusionTest::onIncrement, this);
    save_ = nh_.serviceClient<unsup_mvs::SaveCloud>("/fusion/save_cloud");
    reset_ = nh_.serviceClient<unsup_mvs::ResetFusion>("/fusion/reset");
    ASSERT_TRUE(save_.waitForExistence(ros::Duration(30.0))) << "fusion did not come up";
    ASSERT_TRUE(wait_for([&] { return estimate_pub_.getNumSubscribers() > 0 && cloud_sub_.getNumPublishers() > 0 &&
                                      increment_sub_.getNumPublishers() > 0; }, 10.0));
    unsup_mvs::ResetFusion r;
    ASSERT_TRUE(reset_.call(r));
    ASSERT_TRUE(nh_.getParam("/fusion/save_dir", dir_));  // save_cloud writes only there
    std::filesystem::create_directories(dir_);
  }
  void onCloud(const sensor_msgs::PointCloud2ConstPtr& m) { cloud_ = m; }
  void onIncrement(const sensor_msgs::PointCloud2ConstPtr& m) {
    increments_++;
    increment_points_ += m->width * m->height;
  }

  unsup_mvs::SaveCloud::Response save(const std::string& path) {
    unsup_mvs::SaveCloud srv;
    srv.request.path = path;
    EXPECT_TRUE(save_.call(srv));
    return srv.response;
  }

  ros::NodeHandle nh_;
  ros::Publisher estimate_pub_;
  ros::Subscriber cloud_sub_, increment_sub_;
  ros::ServiceClient save_, reset_;
  sensor_msgs::PointCloud2ConstPtr cloud_;
  int increments_ = 0;
  size_t increment_points_ = 0;
  std::string dir_;
};

TEST_F(FusionTest, PlaneBecomesACloudAndIsSaved) {
  umvs_test::RosoutCapture log(nh_);
  ros::Time last_stamp;
  for (uint32_t i = 0; i < 5; ++i) {
    const auto e = make_estimate(i, 0.1 * i);
    last_stamp = e.header.stamp;
    estimate_pub_.publish(e);
    ros::WallDuration(0.1).sleep();
  }
  // min_agreeing_views 2 (see fusion.test): from the third estimate on, pixels are confirmed.
  ASSERT_TRUE(wait_for([&] { return cloud_ && cloud_->header.stamp == last_stamp; }, 20.0)) << log.all();
  const auto& c = *cloud_;
  EXPECT_EQ(c.header.frame_id, "world");
  ASSERT_GT(c.width * c.height, 1000u);
  EXPECT_EQ(increment_points_, c.width * c.height) << "the increments add up to the map";
  std::vector<std::string> names;
  for (const auto& f : c.fields) names.push_back(f.name);
  EXPECT_EQ(names, (std::vector<std::string>{"x", "y", "z", "rgb", "confidence", "views"}));
  sensor_msgs::PointCloud2ConstIterator<float> x(c, "x"), y(c, "y"), z(c, "z"), conf(c, "confidence");
  sensor_msgs::PointCloud2ConstIterator<uint8_t> r(c, "r"), g(c, "g"), views(c, "views");
  // Every camera sees x in [cx - 1.9, cx + 1.9], y in [-1.4, 1.4] on the plane (3 m * 31.5 / 50).
  for (size_t i = 0; i < c.width * c.height; ++i, ++x, ++y, ++z, ++r, ++g, ++conf, ++views) {
    ASSERT_NEAR(*z, kPlaneZ, 1e-3);
    ASSERT_TRUE(*x > -2.0f && *x < 2.4f) << *x;
    ASSERT_TRUE(std::abs(*y) < 1.5f) << *y;
    ASSERT_EQ(*r, 200);
    ASSERT_EQ(*g, 0);
    ASSERT_NEAR(*conf, 0.9f, 1e-5);  // every pixel's confidence
    ASSERT_GE(*views, 2);            // min_agreeing_views
  }

  const std::string path = dir_ + "/cloud.ply";
  auto res = save(path);
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_EQ(res.num_points, c.width * c.height);
  const umvs::PointCloud saved = umvs::read_ply(path);
  ASSERT_EQ(saved.size(), res.num_points);
  for (const auto& p : saved.points) ASSERT_NEAR(p.z(), kPlaneZ, 1e-3);

  // The same map as a PCD that PCL opens: every point, with our fields.
  res = save(dir_ + "/cloud.pcd");
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_EQ(res.num_points, c.width * c.height);
  pcl::PCLPointCloud2 blob;
  ASSERT_EQ(pcl::io::loadPCDFile(dir_ + "/cloud.pcd", blob), 0);
  std::vector<std::string> pcd_fields;
  for (const auto& f : blob.fields) pcd_fields.push_back(f.name);
  EXPECT_EQ(pcd_fields, names);
  pcl::PointCloud<umvs::FusedPoint> pcd;
  ASSERT_EQ(pcl::io::loadPCDFile(dir_ + "/cloud.pcd", pcd), 0);
  ASSERT_EQ(pcd.size(), c.width * c.height);
  for (const auto& p : pcd) {
    ASSERT_NEAR(p.z, kPlaneZ, 1e-3);
    ASSERT_EQ(p.r, 200);
    ASSERT_GE(p.views, 2);
  }

  // Another extension is refused with its name, and nothing is written.
  res = save(dir_ + "/cloud.txt");
  EXPECT_FALSE(res.success);
  EXPECT_NE(res.message.find("'.txt'"), std::string::npos) << res.message;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/cloud.txt"));

  // A path that cannot be written (its folder would be inside a regular file): a clear failure.
  res = save(path + "/cloud.ply");
  EXPECT_FALSE(res.success);
  EXPECT_NE(res.message.find(path), std::string::npos) << res.message;

  // After reset the cloud is empty, and saving it does not replace the good file.
  const auto size_before = std::filesystem::file_size(path);
  unsup_mvs::ResetFusion r2;
  ASSERT_TRUE(reset_.call(r2));
  EXPECT_TRUE(r2.response.success);
  res = save(path);
  EXPECT_FALSE(res.success);
  EXPECT_EQ(res.num_points, 0u);
  EXPECT_EQ(std::filesystem::file_size(path), size_before);
  ASSERT_TRUE(wait_for([&] { return cloud_ && cloud_->width == 0; }, 5.0)) << "the empty map is published after reset";
}

// The plane's depth maps ray-cast into the OctoMap: the grid of the band around z = 3 is occupied
// where the cameras saw the plane, in the world frame; save_map writes a .bt octomap reads, only
// inside ~save_dir.
TEST_F(FusionTest, OccupancyGridAndOctoMap) {
  GridListener listener(nh_);
  const auto& grid = listener.grid;
  ASSERT_TRUE(wait_for([&] { return grid != nullptr; }, 10.0));
  ros::Time last_stamp;
  for (uint32_t i = 0; i < 5; ++i) {
    const auto e = make_estimate(20 + i, 0.1 * i);
    last_stamp = e.header.stamp;
    estimate_pub_.publish(e);
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(wait_for([&] { return grid && grid->header.stamp == last_stamp; }, 20.0));
  EXPECT_EQ(grid->header.frame_id, "world");
  EXPECT_FLOAT_EQ(grid->info.resolution, 0.05f);
  ASSERT_EQ(grid->data.size(), static_cast<size_t>(grid->info.width) * grid->info.height);
  // The extent's footprint (the default 50 x 50 m floor), mostly never seen: unknown.
  EXPECT_EQ(grid->info.width, 1000u);
  EXPECT_EQ(grid->info.height, 1000u);
  EXPECT_DOUBLE_EQ(grid->info.origin.position.x, -25.0);
  EXPECT_GT(std::count(grid->data.begin(), grid->data.end(), int8_t{-1}), 900000);
  // The cameras (x 0 .. 0.4, 64 x 48 px at f = 50) see the plane z = 3 over x -1.92 .. 2.32, y -1.44 .. 1.44.
  int occupied = 0, outside = 0;
  double min_x = 1e9, max_x = -1e9, min_y = 1e9, max_y = -1e9;
  for (uint32_t j = 0; j < grid->info.height; ++j) {
    for (uint32_t i = 0; i < grid->info.width; ++i) {
      if (grid->data[j * grid->info.width + i] != 100) continue;
      ++occupied;
      const double x = grid->info.origin.position.x + (i + 0.5) * grid->info.resolution;
      const double y = grid->info.origin.position.y + (j + 0.5) * grid->info.resolution;
      outside += x < -2.05 || x > 2.45 || std::abs(y) > 1.55;
      min_x = std::min(min_x, x), max_x = std::max(max_x, x), min_y = std::min(min_y, y), max_y = std::max(max_y, y);
    }
  }
  // Rays every 2nd pixel (~12 cm apart on the plane) from 5 cameras 10 cm apart: over 1,000 cells,
  // spread over the whole footprint, none outside it.
  EXPECT_GT(occupied, 1000);
  EXPECT_EQ(outside, 0);
  EXPECT_LT(min_x, -1.7);
  EXPECT_GT(max_x, 2.1);
  EXPECT_LT(min_y, -1.2);
  EXPECT_GT(max_y, 1.2);

  ros::ServiceClient save_map = nh_.serviceClient<unsup_mvs::SaveCloud>("/fusion/save_map");
  unsup_mvs::SaveCloud srv;
  srv.request.path = "plane.bt";
  ASSERT_TRUE(save_map.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  octomap::OcTree tree(dir_ + "/plane.bt");
  EXPECT_EQ(tree.getResolution(), 0.05);
  const octomap::OcTreeNode* on_plane = tree.search(0.2, 0.0, 3.0);
  const octomap::OcTreeNode* in_front = tree.search(0.2, 0.0, 1.5);  // between the cameras and the plane
  ASSERT_TRUE(on_plane && in_front) << "both were observed";
  EXPECT_TRUE(tree.isNodeOccupied(on_plane));
  EXPECT_FALSE(tree.isNodeOccupied(in_front));
  for (const char* bad : {"plane.ply", "../escaped.bt"}) {
    srv.request.path = bad;
    ASSERT_TRUE(save_map.call(srv));
    EXPECT_FALSE(srv.response.success) << bad;
    EXPECT_NE(srv.response.message.find("refused"), std::string::npos) << srv.response.message;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/plane.ply"));
}

// The plane seen with a 0.4 x 0.4 m square 1 m in front of it (world z = 2, centred on x = y = 0).
unsup_mvs::DepthEstimate estimate_with_object(uint32_t id, double x) {
  auto e = make_estimate(id, x);
  constexpr double kObjectZ = kPlaneZ - 1.0;
  auto depth = torch::full({umvs_test::kPlaneHeight, umvs_test::kPlaneWidth}, static_cast<float>(kPlaneZ));
  auto d = depth.accessor<float, 2>();
  for (int v = 0; v < umvs_test::kPlaneHeight; ++v) {
    for (int u = 0; u < umvs_test::kPlaneWidth; ++u) {
      const double X = x + (u - (umvs_test::kPlaneWidth - 1) / 2.0) * kObjectZ / umvs_test::kPlaneFocal;
      const double Y = (v - (umvs_test::kPlaneHeight - 1) / 2.0) * kObjectZ / umvs_test::kPlaneFocal;
      if (std::abs(X) <= 0.2 && std::abs(Y) <= 0.2) d[v][u] = static_cast<float>(kObjectZ);
    }
  }
  e.depth = umvs::float_to_image_msg(depth, e.header);
  return e;
}

TEST_F(FusionTest, AnObjectThatLeavesIsRemovedFromTheCloudAndTheGrid) {
  umvs_test::RosoutCapture log(nh_);
  GridListener listener(nh_);
  const auto& grid = listener.grid;
  ASSERT_TRUE(wait_for([&] { return grid != nullptr; }, 10.0));
  // At the node's defaults (every pixel a ray, 5 cm leaves), live: only the grid's height band
  // moves to the object (restored at the end).
  ASSERT_EQ(nh_.param("/fusion/occupancy/pixel_stride", 1), 1) << "fusion.test must keep the default stride";
  reconfigure("/fusion", Request().set("occupancy_grid_min_z", 1.9).set("occupancy_grid_max_z", 2.1));
  auto occupied_cells = [&] { return std::count(grid->data.begin(), grid->data.end(), int8_t{100}); };
  using Point = std::tuple<float, float, float>;
  auto points = [&](bool object) {
    std::set<Point> out;
    sensor_msgs::PointCloud2ConstIterator<float> x(*cloud_, "x"), y(*cloud_, "y"), z(*cloud_, "z");
    for (size_t i = 0; i < cloud_->width * cloud_->height; ++i, ++x, ++y, ++z) {
      if ((*z < kPlaneZ - 0.5) == object) out.insert({*x, *y, *z});
    }
    return out;
  };
  auto replay = [&](uint32_t first_id, int count, bool with_object) {
    ros::Time last;
    for (int i = 0; i < count; ++i) {
      const double x = 0.1 * (i % 5);  // the cameras' path, again and again
      const auto e = with_object ? estimate_with_object(first_id + i, x) : make_estimate(first_id + i, x);
      last = e.header.stamp;
      estimate_pub_.publish(e);
      ros::WallDuration(0.1).sleep();
    }
    ASSERT_TRUE(wait_for([&] { return cloud_ && cloud_->header.stamp == last && grid && grid->header.stamp == last; },
                         20.0))
        << log.all();
  };
  replay(40, 5, true);
  const auto plane = points(false);
  const size_t object_points = points(true).size();
  const long object_cells = occupied_cells();
  EXPECT_GT(object_points, 50u) << "the object is in the cloud";
  EXPECT_GT(object_cells, 20) << "the object is in the grid";

  // It has gone: three more passes. An occupied cell at octomap's clamp needs nine rays through it.
  replay(60, 15, false);
  size_t plane_kept = 0;
  for (const auto& p : points(false)) plane_kept += plane.count(p);
  std::printf("[ figures  ] object: %zu points, %ld grid cells; after three passes without it %zu and %ld; the plane "
              "kept %zu of its %zu points\n",
              object_points, object_cells, points(true).size(), static_cast<long>(occupied_cells()), plane_kept,
              plane.size());
  EXPECT_EQ(points(true).size(), 0u);
  EXPECT_EQ(occupied_cells(), 0);
  EXPECT_GT(listener.updates, 0) << "the grid followed through its changed windows";
  EXPECT_GE(static_cast<double>(plane_kept), 0.99 * plane.size());
  reconfigure("/fusion", Request().set("occupancy_grid_min_z", 2.8).set("occupancy_grid_max_z", 3.2));
}

TEST_F(FusionTest, BadEstimatesAreLoggedAndSkipped) {
  umvs_test::RosoutCapture log(nh_);
  auto other_frame = make_estimate(50, 0.0);
  other_frame.world_frame = "map";
  EXPECT_TRUE(umvs_test::publish_until_logged(estimate_pub_, other_frame, log, "this node fuses in 'world'", 10.0))
      << log.all();
  // Errors are throttled to one per 2 s: each bad estimate is resent until its error shows.
  auto nan_pose = make_estimate(51, 0.0);
  nan_pose.pose.position.z = std::nan("");
  EXPECT_TRUE(umvs_test::publish_until_logged(estimate_pub_, nan_pose, log, "pose has non-finite values", 10.0))
      << log.all();
  // A pose 1.5 km away (a bad fix): its rays stay out of the occupancy map, with one warning.
  auto far_away = make_estimate(53, 1500.0);
  EXPECT_TRUE(umvs_test::publish_until_logged(estimate_pub_, far_away, log, "outside the occupancy map's extent", 10.0))
      << log.all();
  auto wrong_depth = make_estimate(52, 0.0);
  wrong_depth.depth.encoding = "mono8";
  EXPECT_TRUE(umvs_test::publish_until_logged(estimate_pub_, wrong_depth, log, "expected a 32FC1 image, got 'mono8'", 10.0))
      << log.all();

  // None of them entered the fusion window: three good estimates still make a cloud.
  for (uint32_t i = 0; i < 3; ++i) {
    estimate_pub_.publish(make_estimate(60 + i, 0.1 * i));
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(wait_for([&] { return cloud_ && cloud_->width > 0; }, 20.0)) << log.all();
  auto res = save(dir_ + "/after_bad.ply");
  EXPECT_TRUE(res.success) << res.message;
}

}  // namespace
