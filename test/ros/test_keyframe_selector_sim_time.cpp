// rostest for keyframe_selector on simulated time that has stopped (a replayed log at its end):
// a frame whose camera transform never comes is skipped after ~tf_timeout seconds of wall time,
// and ~flush still answers. tf2's own wait counts ROS time and would block the node for ever.
#include <rosgraph_msgs/Clock.h>
#include <std_srvs/Trigger.h>

#include <chrono>
#include <future>

#include "rostest_util.h"

namespace {

using umvs_test::wait_for;

TEST(KeyframeSelectorSimTime, AFrameWithoutItsTransformDoesNotBlockTheNodeWhenTheClockStops) {
  ros::NodeHandle nh;
  umvs_test::RosoutCapture log(nh);
  ros::Publisher clock_pub = nh.advertise<rosgraph_msgs::Clock>("/clock", 1, true);
  ros::Publisher image_pub = nh.advertise<sensor_msgs::Image>("/cam/image", 1);
  ros::Publisher info_pub = nh.advertise<sensor_msgs::CameraInfo>("/cam/camera_info", 1);
  ASSERT_TRUE(wait_for([&] { return image_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
                                    clock_pub.getNumSubscribers() > 0; }, 30.0))
      << "keyframe_selector did not come up";
  rosgraph_msgs::Clock clock;
  clock.clock = ros::Time(100.0);  // and never again
  clock_pub.publish(clock);
  // The latched clock reaches the node as it connects; its arrival is not observable from here (and
  // before it the node's tf2 would wait on wall time, passing this test for the wrong reason).
  ros::WallDuration(0.5).sleep();

  sensor_msgs::CameraInfo info;
  info.header.stamp = clock.clock;
  info.header.frame_id = "cam_without_tf";
  info.width = 64;
  info.height = 48;
  info.K = {50, 0, 31.5, 0, 50, 23.5, 0, 0, 1};
  info.P = {50, 0, 31.5, 0, 0, 50, 23.5, 0, 0, 0, 1, 0};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.distortion_model = "plumb_bob";
  info.D = {0, 0, 0, 0, 0};
  sensor_msgs::Image image;
  image.header = info.header;
  image.width = 64;
  image.height = 48;
  image.encoding = "rgb8";
  image.step = 64 * 3;
  image.data.assign(64 * 48 * 3, 128);
  image_pub.publish(image);
  info_pub.publish(info);
  EXPECT_TRUE(log.wait_for("no transform", 10.0)) << log.all();

  // The flush service is served by the same callback thread: it answers only if the frame let go.
  auto answer = std::async(std::launch::async, [] {
    std_srvs::Trigger flush;
    return ros::service::call("/keyframe_selector/flush", flush) ? flush.response.message : std::string("call failed");
  });
  ASSERT_EQ(answer.wait_for(std::chrono::seconds(10)), std::future_status::ready) << "~flush did not answer";
  EXPECT_EQ(answer.get(), "sent 0 keyframe set(s); 0 keyframe(s) still wait for neighbours");
}

}  // namespace
