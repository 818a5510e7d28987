// rostest: the inference nodelet's depth camera (REP 118, OpenNI-style names) run through four of
// Debian's depth_image_proc nodelets (depth_camera.test): point_cloud_xyz makes the points our depth
// map implies, pixel for pixel, with NaN where the map has no estimate or its confidence is below
// the floor; point_cloud_xyzrgb, with no remap, the same points in the reference's colours;
// register, the same depth (one camera); convert_metric, our 16UC1 millimetres back to metres.
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <tuple>

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
  std::vector<sensor_msgs::PointCloud2ConstPtr> coloured_clouds;
  std::vector<sensor_msgs::ImageConstPtr> registered, metric;
  ros::Subscriber xyzrgb_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "/depth_registered/points", 10, [&](const sensor_msgs::PointCloud2ConstPtr& m) { coloured_clouds.push_back(m); });
  ros::Subscriber register_sub = nh.subscribe<sensor_msgs::Image>(
      "/reg/depth_registered/image_rect", 10, [&](const sensor_msgs::ImageConstPtr& m) { registered.push_back(m); });
  ros::Subscriber metric_sub = nh.subscribe<sensor_msgs::Image>(
      "/metric/image", 10, [&](const sensor_msgs::ImageConstPtr& m) { metric.push_back(m); });
  ros::Publisher keyframes = nh.advertise<unsup_mvs::KeyframeSet>("/keyframes", 10);
  ASSERT_TRUE(wait_for([&] { return keyframes.getNumSubscribers() > 0; }, 30.0));

  auto set = umvs_test::keyframe_set(5, {128, 96, 100.0, "cam"});
  // The reference image was taken before the set was sent: outputs must carry the image's stamp.
  set.reference_image.header.stamp = set.header.stamp - ros::Duration(0.25);
  // depth_image_proc subscribes to the depth camera once /depth/points has a subscriber; a set
  // sent before that reaches only our own topics, so send until a cloud comes.
  const auto all_came = [&] {
    return !clouds.empty() && !coloured_clouds.empty() && !registered.empty() && !metric.empty();
  };
  for (int attempt = 0; attempt < 45 && !all_came(); ++attempt) {
    keyframes.publish(set);
    wait_for(all_came, 2.0);
  }
  ASSERT_FALSE(clouds.empty()) << "no cloud from point_cloud_xyz";
  ASSERT_FALSE(coloured_clouds.empty()) << "no cloud from point_cloud_xyzrgb";
  ASSERT_FALSE(registered.empty()) << "no depth from register";
  ASSERT_FALSE(metric.empty()) << "no depth from convert_metric";
  ASSERT_TRUE(wait_for([&] { return !estimates.empty() && !colours.empty(); }, 30.0));
  const auto& cloud = *clouds.back();
  // The estimate of the reference image whose stamp the cloud carries.
  const auto found = std::find_if(estimates.rbegin(), estimates.rend(),
                                  [&](const auto& e) { return e->header.stamp == cloud.header.stamp; });
  ASSERT_NE(found, estimates.rend()) << "no estimate has the cloud's stamp";
  const auto estimate = *found;
  EXPECT_EQ(cloud.header.frame_id, "cam");  // the reference's optical frame
  EXPECT_EQ(cloud.header.stamp, set.reference_image.header.stamp);
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
  // point_cloud_xyzrgb: the same points, each in its pixel's colour.
  const auto& coloured = *coloured_clouds.back();
  ASSERT_EQ(coloured.width * coloured.height, cloud.width * cloud.height);
  const auto& rgb = estimate->image;
  ASSERT_EQ(rgb.encoding, "rgb8");
  sensor_msgs::PointCloud2ConstIterator<float> cz(coloured, "z");
  sensor_msgs::PointCloud2ConstIterator<uint8_t> cr(coloured, "r"), cg(coloured, "g"), cb(coloured, "b");
  int coloured_known = 0, colour_mismatches = 0, depth_mismatches = 0;
  for (size_t i = 0; i < cloud.width * cloud.height; ++i, ++cz, ++cr, ++cg, ++cb) {
    const bool known_pixel = confidence[i] >= kFloor && depth[i] > 0;
    if (!known_pixel) {
      depth_mismatches += !std::isnan(*cz);
      continue;
    }
    ++coloured_known;
    depth_mismatches += std::abs(*cz - depth[i]) > 1e-6f;
    colour_mismatches += *cr != rgb.data[3 * i] || *cg != rgb.data[3 * i + 1] || *cb != rgb.data[3 * i + 2];
  }
  EXPECT_EQ(coloured_known, known);
  EXPECT_EQ(depth_mismatches, 0);
  EXPECT_EQ(colour_mismatches, 0);
  // register (depth and colour are one camera): the same depth; convert_metric: our millimetres in
  // metres, within half a millimetre, unknown where we said unknown.
  for (const auto& [name, image, tolerance] : {std::tuple{"register", registered.back(), 1e-5f},
                                               std::tuple{"convert_metric", metric.back(), 5e-4f}}) {
    ASSERT_EQ(image->encoding, "32FC1") << name;
    ASSERT_EQ(image->width * image->height, cloud.width * cloud.height) << name;
    EXPECT_EQ(image->header.stamp, cloud.header.stamp) << name;
    const float* out = reinterpret_cast<const float*>(image->data.data());
    int wrong = 0, compared = 0;
    for (size_t i = 0; i < cloud.width * cloud.height; ++i) {
      const bool known_pixel = confidence[i] >= kFloor && depth[i] > 0;
      // depth_image_proc marks unknown pixels NaN or 0 depending on the nodelet.
      if (!known_pixel) {
        wrong += std::isfinite(out[i]) && out[i] != 0.0f;
        continue;
      }
      ++compared;
      wrong += !(std::abs(out[i] - depth[i]) <= tolerance);
    }
    EXPECT_EQ(compared, known) << name;
    EXPECT_EQ(wrong, 0) << name << ": pixels that differ from our depth map";
  }

  // The model's confidence straddles 0.99 on these images (0.79 .. 1): both kinds of pixel are checked.
  const int n = static_cast<int>(cloud.width * cloud.height);
  std::vector<float> sorted(confidence, confidence + n);
  std::sort(sorted.begin(), sorted.end());
  EXPECT_GT(known, 0) << "confidence " << sorted.front() << " .. " << sorted[n / 2] << " .. " << sorted.back();
  EXPECT_GT(unknown, 0) << "confidence " << sorted.front() << " .. " << sorted[n / 2] << " .. " << sorted.back();
}

}  // namespace
