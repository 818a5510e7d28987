// Fault injection for ROS messages where they enter the nodes (docs/reliability.md): image
// headers that claim more than their data holds, hostile sizes, unknown encodings.
#include <gtest/gtest.h>
#include <torch/torch.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "test_util.h"
#include "unsup_mvs/io/ros/bag_io.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace umvs {
namespace {

sensor_msgs::Image rgb8(uint32_t width, uint32_t height) {
  sensor_msgs::Image m;
  m.width = width;
  m.height = height;
  m.encoding = "rgb8";
  m.step = width * 3;
  m.data.assign(static_cast<size_t>(m.step) * height, 7);
  return m;
}

std::string refusal(const sensor_msgs::Image& m, uint64_t max_pixels = 1u << 24) {
  try {
    check_image_msg(m, max_pixels);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ImageMessages, TruncatedImagesAreRefusedWhereTheyEnter) {
  EXPECT_EQ(refusal(rgb8(64, 48)), "");
  auto truncated = rgb8(64, 48);
  truncated.data.resize(truncated.data.size() - 1);  // the last row one byte short
  EXPECT_NE(refusal(truncated).find("truncated image: 9215 bytes of data, step 192 x height 48 needs 9216"),
            std::string::npos) << refusal(truncated);
  EXPECT_THROW(image_msg_to_rgb8(truncated), std::invalid_argument);
  auto half = rgb8(64, 48);
  half.data.resize(half.data.size() / 2);
  EXPECT_NE(refusal(half).find("truncated image"), std::string::npos);

  auto short_step = rgb8(64, 48);
  short_step.step = 64 * 3 - 1;
  EXPECT_NE(refusal(short_step).find("row step 191 is shorter than a 64x48 rgb8 row (192 bytes)"), std::string::npos)
      << refusal(short_step);
}

TEST(ImageMessages, HostileSizesAndEncodingsAreRefused) {
  auto huge = rgb8(2, 2);
  huge.width = 100000;
  huge.height = 100000;
  huge.step = 300000;  // step * height overflows 32 bits
  EXPECT_NE(refusal(huge, std::numeric_limits<uint64_t>::max()).find("truncated image"), std::string::npos);
  EXPECT_NE(refusal(huge).find("100000x100000 = 10000000000 pixels, more than the limit of 16777216"), std::string::npos)
      << refusal(huge);
  auto zero = rgb8(2, 2);
  zero.height = 0;
  EXPECT_NE(refusal(zero).find("zero size"), std::string::npos);
  auto unknown = rgb8(2, 2);
  unknown.encoding = "yuv9000";
  EXPECT_NE(refusal(unknown).find("unknown image encoding 'yuv9000'"), std::string::npos);
  EXPECT_EQ(refusal(rgb8(4096, 4096)), "");
  EXPECT_NE(refusal(rgb8(4097, 4096)).find("more than the limit"), std::string::npos);
}

std::string camera_info_refusal(const sensor_msgs::CameraInfo& info) {
  try {
    camera_from_info(info, false);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(CameraInfoMessages, ZeroOrNaNIntrinsicsAreRefused) {
  sensor_msgs::CameraInfo info;
  info.width = 64;
  info.height = 48;
  info.K = {50, 0, 31.5, 0, 50, 23.5, 0, 0, 1};
  EXPECT_EQ(camera_info_refusal(info), "");
  auto zero_focal = info;
  zero_focal.K[0] = 0.0;
  EXPECT_NE(camera_info_refusal(zero_focal).find("focal length is zero"), std::string::npos);
  auto nan_center = info;
  nan_center.K[2] = std::nan("");
  EXPECT_NE(camera_info_refusal(nan_center).find("intrinsics contain NaN or infinity"), std::string::npos);
  auto all_zero = info;
  all_zero.K = {};
  EXPECT_NE(camera_info_refusal(all_zero), "");
  auto no_size = info;
  no_size.width = 0;
  EXPECT_NE(camera_info_refusal(no_size).find("zero image size"), std::string::npos);
}

// Poses and tf transforms (tf2_eigen, ros_conversions): the same rigid transform either way, the
// quaternion normalised when nearly unit, refused when not.
TEST(PoseMessages, TransformsAndPosesGiveTheSameMatrixAndBadRotationsAreRefused) {
  geometry_msgs::Transform quarter_turn;  // 90 degrees about z, then (1, 2, 3)
  quarter_turn.translation.x = 1;
  quarter_turn.translation.y = 2;
  quarter_turn.translation.z = 3;
  quarter_turn.rotation.z = std::sqrt(0.5);
  quarter_turn.rotation.w = std::sqrt(0.5);
  Eigen::Matrix4d expected;
  expected << 0, -1, 0, 1,  //
      1, 0, 0, 2,           //
      0, 0, 1, 3,           //
      0, 0, 0, 1;
  EXPECT_TRUE(transform_to_matrix(quarter_turn).isApprox(expected, 1e-12)) << transform_to_matrix(quarter_turn);
  EXPECT_TRUE(pose_to_matrix(matrix_to_pose(expected)).isApprox(expected, 1e-12));
  EXPECT_TRUE(transform_to_matrix(matrix_to_transform(expected)).isApprox(expected, 1e-12));

  auto nearly_unit = quarter_turn;  // norm 1.0005: used normalised, not as a scaled rotation
  nearly_unit.rotation.z *= 1.0005;
  nearly_unit.rotation.w *= 1.0005;
  EXPECT_TRUE(transform_to_matrix(nearly_unit).isApprox(expected, 1e-12)) << transform_to_matrix(nearly_unit);

  auto refusal = [](const geometry_msgs::Transform& t) {
    try {
      transform_to_matrix(t);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  auto scaled = quarter_turn;
  scaled.rotation.w *= 1.1;
  EXPECT_NE(refusal(scaled).find("not a unit quaternion"), std::string::npos) << refusal(scaled);
  auto nan_translation = quarter_turn;
  nan_translation.translation.y = std::nan("");
  EXPECT_EQ(refusal(nan_translation), "pose has non-finite values");
  geometry_msgs::Pose zero_rotation;  // all-zero quaternion: a default-constructed message
  EXPECT_THROW(pose_to_matrix(zero_rotation), std::invalid_argument);
}

TEST(BagWriter, NeverWritesThroughALinkPlantedAtTheOldTemporaryName) {
  namespace fs = std::filesystem;
  const auto dir = test::temp_dir("bag_planted_tmp");
  std::ofstream(dir + "/victim.txt") << "precious";
  // The name the writer used to pick.
  fs::create_symlink(dir + "/victim.txt", dir + "/log.bag.tmp-" + std::to_string(::getpid()) + ".bag");
  BagWriter writer(dir + "/log.bag");
  PosedImage frame;
  frame.stamp = 1.0;
  frame.camera.width = frame.camera.height = 8;
  frame.camera.K << 10, 0, 3.5, 0, 10, 3.5, 0, 0, 1;
  frame.image = torch::zeros({8, 8, 3}, torch::kUInt8);
  writer.write(frame);
  writer.close();
  std::ifstream victim(dir + "/victim.txt");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(victim), {}), "precious");
  EXPECT_FALSE(fs::is_symlink(dir + "/log.bag"));
  EXPECT_GT(fs::file_size(dir + "/log.bag"), 1000u);
}

}  // namespace
}  // namespace umvs
