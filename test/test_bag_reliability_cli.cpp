// Fault injection against the bag readers of the command line (docs/reliability.md, "Command
// line"): a log without /tf, and paths with shell metacharacters.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <torch/torch.h>

#include <filesystem>

#include "cli_test_util.h"
#include "unsup_mvs/io/ros/bag_io.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/io/ros/bag_training_data.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::Result;
using test::run_umvs;

// Images and CameraInfo of a synthetic room, but no /tf: the poses were never recorded.
std::string bag_without_tf(const std::string& dir) {
  SynthConfig c;
  c.num_views = 4;
  c.width = 64;
  c.height = 64;
  c.supersample = 1;
  c.gt_cloud_samples = 0;
  const SynthScene scene = render_synthetic_scene(c);
  const std::string path = dir + "/no_tf.bag";
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  const BagTopics topics;
  for (size_t i = 0; i < scene.views.size(); ++i) {
    std_msgs::Header header;
    header.stamp = ros::Time(100.0 + static_cast<double>(i));
    header.frame_id = topics.camera_frame;
    bag.write(topics.camera_info, header.stamp, camera_info_from_camera(scene.views[i].camera, header));
    bag.write(topics.image, header.stamp, rgb8_to_image_msg(scene.views[i].image, header));
  }
  bag.close();
  return path;
}

TEST(BagFaults, ALogWithoutTfSaysNoTransformWasFoundForTheCameraFrame) {
  const std::string dir = test::temp_dir("no_tf");
  const std::string bag = bag_without_tf(dir);
  const std::string expected = "no transform found from 'world' to the camera frame 'camera_optical_frame'";

  Result inspect = run_umvs("bag --inspect " + bag);
  EXPECT_EQ(inspect.status, 1) << inspect.output;
  EXPECT_TRUE(contains(inspect.output, "4 images on /camera/image_rect_color, 0 posed")) << inspect.output;
  EXPECT_TRUE(contains(inspect.output, expected)) << inspect.output;
  EXPECT_FALSE(contains(inspect.output, "Duration")) << inspect.output;

  BagDataConfig config;
  EXPECT_THAT([&] { read_bag_keyframes({bag}, config, nullptr); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("4 without a transform from 'world'"), testing::HasSubstr(expected))));
  Result train = run_umvs("train --bag " + bag + " --width 64 --height 64 --num-depth 8 --steps 1 --out " + dir + "/run");
  EXPECT_EQ(train.status, 1) << train.output;
  EXPECT_TRUE(contains(train.output, expected)) << train.output;
  EXPECT_FALSE(fs::exists(dir + "/run"));
}

TEST(BagFaults, ShellMetacharactersInBagPathsAreJustCharacters) {
  const std::string data = test::scene("meta_data");
  const std::string dir = test::temp_dir("meta");
  // (A shell running this name would create "pwned" in the working directory.)
  const std::string bag = dir + "/a;touch pwned;$(id)`id`.bag";
  auto quote = [](const std::string& s) { return "'" + s + "'"; };
  Result written = run_umvs("bag --data " + data + " --out " + quote(bag));
  ASSERT_EQ(written.status, 0) << written.output;
  EXPECT_TRUE(fs::exists(bag));
  Result inspect = run_umvs("bag --inspect " + quote(bag));
  EXPECT_EQ(inspect.status, 0) << inspect.output;
  EXPECT_TRUE(contains(inspect.output, "5 posed and calibrated")) << inspect.output;
  EXPECT_FALSE(fs::exists("pwned"));
  EXPECT_FALSE(fs::exists(dir + "/pwned"));
}

}  // namespace
}  // namespace umvs
