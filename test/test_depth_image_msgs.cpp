// The depth camera's images (io/ros/ros_conversions.h): 32FC1 metres with NaN where unknown, and the
// same as 16UC1 millimetres with 0 where unknown, as OpenNI cameras and rtabmap expect.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>

#include "unsup_mvs/io/ros/ros_conversions.h"

namespace umvs {
namespace {

TEST(DepthImageMsgs, MillimetresWithZeroWhereUnknown) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Depth, confidence: known, below the floor, no estimate, NaN, farther than 16 bits of mm, sub-mm.
  const auto depth = torch::tensor({1.2344f, 2.0f, 0.0f, nan, 70.0f, 0.0004f}).view({2, 3});
  const auto confidence = torch::tensor({0.9f, 0.3f, 0.9f, 0.9f, 0.9f, 0.9f}).view({2, 3});
  std_msgs::Header header;
  header.frame_id = "cam";
  header.stamp = ros::Time(12, 345);
  const sensor_msgs::Image metres = depth_camera_image_msg(depth, confidence, 0.5, header);
  const sensor_msgs::Image mm = depth_camera_image_16uc1_msg(metres);
  EXPECT_EQ(mm.encoding, "16UC1");
  EXPECT_EQ(mm.width, 3u);
  EXPECT_EQ(mm.height, 2u);
  EXPECT_EQ(mm.step, 6u);
  EXPECT_EQ(mm.is_bigendian, 0);
  EXPECT_EQ(mm.header.frame_id, "cam");
  EXPECT_EQ(mm.header.stamp, header.stamp);
  ASSERT_EQ(mm.data.size(), 12u);
  const auto value = [&](int i) { return mm.data[2 * i] | (mm.data[2 * i + 1] << 8); };
  EXPECT_EQ(value(0), 1234);  // rounded to the nearest millimetre
  EXPECT_EQ(value(1), 0) << "below the confidence floor";
  EXPECT_EQ(value(2), 0) << "no estimate";
  EXPECT_EQ(value(3), 0) << "NaN";
  EXPECT_EQ(value(4), 0) << "beyond 65.535 m";
  EXPECT_EQ(value(5), 0) << "rounds to 0 mm";
  // What it was made from says the same in metres.
  const auto back = image_msg_to_float(metres);
  EXPECT_NEAR(back[0][0].item<float>(), 1.2344f, 1e-6f);
  for (int i : {1, 2, 3}) EXPECT_TRUE(std::isnan(back.view({-1})[i].item<float>())) << i;
  sensor_msgs::Image wrong = metres;
  wrong.encoding = "16UC1";
  EXPECT_THROW(depth_camera_image_16uc1_msg(wrong), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
