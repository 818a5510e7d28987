// rostest: the inference nodelet's depth/image and depth/camera_info (REP 118) are a depth camera
// that depth_image_proc's point_cloud_xyz turns into the points our depth map implies, pixel for
// pixel, with NaN where the map has no estimate or its confidence is below the floor.
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "rostest_util.h"
#include "test_messages.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"

namespace {

using umvs_test::wait_for;
constexpr float kFloor = 0.99f;  // depth_camera_min_confidence in depth_camera.test

TEST(DepthCamera, DepthImageProcMakesTheCloudOfOurDepthMap) {
  ros::NodeHandle nh;
  // The node serves the shipped model (depth_camera.test); its services up = the model is loaded.
  ros::ServiceClient reload = nh.serviceClient<unsup_mvs::ReloadModel>("/inference/reload_model");
  ASSERT_TRUE(reload.waitForExistence(ros::Duration(30.0))) << "inference did not come up";

  std::vector<unsup_mvs::DepthEstimateConstPtr> estimates;
  std::vector<sensor_msgs::PointCloud2ConstPtr> clouds;
  std::vector<sensor_msgs::ImageConstPtr> colours;
  ros::Subscriber estimate_sub = nh.subscribe<unsup_mvs::DepthEstimate>(
      "/depth_estimate", 10, [&](const unsup_mvs::DepthEstimateConstPtr& m) { estimates.push_back(m); });
  ros::Subscriber cloud_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "/depth/points", 10, [&](const sensor_msgs::PointCloud2ConstPtr& m) { clouds.push_back(m); });
  ros::Subscriber rgb_sub = nh.subscribe<sensor_msgs::Image>(
      "/depth/rgb", 10, [&](const sensor_msgs::ImageConstPtr& m) { colours.push_back(m); });
  ros::Publisher keyframes = nh.advertise<unsup_mvs::KeyframeSet>("/keyframes", 10);
  ASSERT_TRUE(wait_for([&] { return keyframes.getNumSubscribers() > 0; }, 30.0));

  const auto set = umvs_test::keyframe_set(5, {128, 96, 100.0, "cam"});
  // depth_image_proc subscribes to the depth camera once /depth/points has a subscriber; a set
  // sent before that reaches only our own topics, so send until a cloud comes.
  for (int attempt = 0; attempt < 45 && clouds.empty(); ++attempt) {
    keyframes.publish(set);
    wait_for([&] { return !clouds.empty(); }, 2.0);
  }
  ASSERT_FALSE(clouds.empty()) << "no cloud from depth_image_proc";
  ASSERT_TRUE(wait_for([&] { return !estimates.empty() && !colours.empty(); }, 30.0));
  const auto& cloud = *clouds.back();
  const auto estimate = *std::find_if(estimates.rbegin(), estimates.rend(),
                                      [&](const auto& e) { return e->header.stamp == cloud.header.stamp; });
  EXPECT_EQ(cloud.header.frame_id, "cam");  // the reference's optical frame
  EXPECT_EQ(cloud.header.stamp, set.header.stamp);
  ASSERT_EQ(cloud.width, estimate->depth.width);
  ASSERT_EQ(cloud.height, estimate->depth.height);
  EXPECT_EQ(colours.back()->width, estimate->depth.width);
  EXPECT_EQ(colours.back()->encoding, "rgb8");

  const float* depth = reinterpret_cast<const float*>(estimate->depth.data.data());
  const float* confidence = reinterpret_cast<const float*>(estimate->confidence.data.data());
  const auto& K = estimate->camera_info.K;
  sensor_msgs::PointCloud2ConstIterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  int known = 0, unknown = 0;
  for (uint32_t v = 0; v < cloud.height; ++v) {
    for (uint32_t u = 0; u < cloud.width; ++u, ++x, ++y, ++z) {
      const size_t i = v * cloud.width + u;
      if (confidence[i] < kFloor || !(depth[i] > 0)) {
        EXPECT_TRUE(std::isnan(*z)) << "pixel " << u << "," << v << " has confidence " << confidence[i];
        ++unknown;
        continue;
      }
      ++known;
      EXPECT_NEAR(*z, depth[i], 1e-6f);
      EXPECT_NEAR(*x, (u - K[2]) * depth[i] / K[0], 1e-5f) << u << "," << v;
      EXPECT_NEAR(*y, (v - K[5]) * depth[i] / K[4], 1e-5f) << u << "," << v;
    }
  }
  // The model's confidence straddles 0.99 on these images (0.79 .. 1): both kinds of pixel are checked.
  const int n = static_cast<int>(cloud.width * cloud.height);
  std::vector<float> sorted(confidence, confidence + n);
  std::sort(sorted.begin(), sorted.end());
  EXPECT_GT(known, 0) << "confidence " << sorted.front() << " .. " << sorted[n / 2] << " .. " << sorted.back();
  EXPECT_GT(unknown, 0) << "confidence " << sorted.front() << " .. " << sorted[n / 2] << " .. " << sorted.back();
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_depth_camera");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
