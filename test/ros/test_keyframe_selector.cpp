// rostest for keyframe_selector: a camera moving along x (tf2 + Image + CameraInfo) gives
// KeyframeSets with the right stamps, frames, neighbours and depth range; bad input (unsupported
// encoding, missing transform, NaN pose, distorted calibration) is logged and skipped, and the
// node keeps working; a camera that stops still gets the set of its last keyframe, and so does a
// log that ends (~flush). With ~compressed (keyframe_selector_compressed.test) the images go as
// png sensor_msgs/CompressedImage on /cam/image/compressed to a selector with
// image_transport:=compressed.
#include <sensor_msgs/CompressedImage.h>
#include <std_srvs/Trigger.h>
#include <tf2_msgs/TFMessage.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>

#include "rostest_util.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace {

using umvs_test::wait_for;

class KeyframeSelectorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ros::NodeHandle("~").param("compressed", compressed_, false);
    if (compressed_) {
      image_pub_ = nh_.advertise<sensor_msgs::CompressedImage>("/cam/image/compressed", 10);
    } else {
      image_pub_ = nh_.advertise<sensor_msgs::Image>("/cam/image", 10);
    }
    info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("/cam/camera_info", 10);
    tf_pub_ = nh_.advertise<tf2_msgs::TFMessage>("/tf", 100);
    sets_sub_ = nh_.subscribe("/keyframes", 20, &KeyframeSelectorTest::onSet, this);
    ASSERT_TRUE(wait_for([&] { return image_pub_.getNumSubscribers() > 0 && info_pub_.getNumSubscribers() > 0 &&
                                      tf_pub_.getNumSubscribers() > 0 && sets_sub_.getNumPublishers() > 0; }, 30.0))
        << "keyframe_selector did not come up";
  }
  void onSet(const unsup_mvs::KeyframeSetConstPtr& m) { sets_.push_back(m); }

  // One frame: the transform world -> frame at `stamp`, then image + camera_info.
  void sendFrame(const geometry_msgs::Pose& pose, const std::string& frame = "cam", const std::string& encoding = "rgb8",
                 bool distorted = false) {
    const ros::Time stamp = ros::Time::now();
    geometry_msgs::TransformStamped tf;
    tf.header.stamp = stamp;
    tf.header.frame_id = "world";
    tf.child_frame_id = frame;
    tf.transform.translation.x = pose.position.x;
    tf.transform.translation.y = pose.position.y;
    tf.transform.translation.z = pose.position.z;
    tf.transform.rotation = pose.orientation;
    tf2_msgs::TFMessage tfm;
    tfm.transforms.push_back(tf);
    tf_pub_.publish(tfm);
    ros::WallDuration(0.03).sleep();
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = frame;
    auto info = umvs_test::make_info(160, 128, 120.0, header);
    if (distorted) info.D[0] = -0.2;
    info_pub_.publish(info);
    const sensor_msgs::Image image = umvs_test::make_image(160, 128, header, 0, encoding);
    if (compressed_) {
      image_pub_.publish(png(image));
    } else {
      image_pub_.publish(image);
    }
    stamps_.push_back(stamp);
    ros::WallDuration(0.05).sleep();
    ros::spinOnce();
  }

  static sensor_msgs::CompressedImage png(const sensor_msgs::Image& image) {
    const torch::Tensor rgb = umvs::image_msg_to_rgb8(image);
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(rgb.size(0), rgb.size(1), CV_8UC3, rgb.data_ptr()), bgr, cv::COLOR_RGB2BGR);
    sensor_msgs::CompressedImage c;
    c.header = image.header;
    c.format = "rgb8; png compressed bgr8";
    cv::imencode(".png", bgr, c.data);
    return c;
  }

  ros::NodeHandle nh_;
  bool compressed_ = false;
  ros::Publisher image_pub_, info_pub_, tf_pub_;
  ros::Subscriber sets_sub_;
  std::vector<unsup_mvs::KeyframeSetConstPtr> sets_;
  std::vector<ros::Time> stamps_;
};

TEST_F(KeyframeSelectorTest, KeyframeSetsFromAMovingCamera) {
  umvs_test::RosoutCapture log(nh_);
  // 0.051 m per frame with a 0.1 m threshold: frames 0, 2, 4, ... are keyframes 0..5. Every
  // keyframe is a reference once, in order, when the next keyframe came (lookahead 1, the
  // default): keyframes 0 and 1 when keyframe 2 gives them a second neighbour, keyframe k > 1
  // with keyframe k + 1; the last one still waits.
  for (int i = 0; i < 12; ++i) sendFrame(umvs_test::make_pose({0.051 * i, 0, 0}));
  ASSERT_TRUE(wait_for([&] { return sets_.size() >= 5; }, 10.0)) << "got " << sets_.size() << " sets";
  ros::WallDuration(0.5).sleep();
  ros::spinOnce();
  ASSERT_EQ(sets_.size(), 5u);
  for (size_t k = 0; k < sets_.size(); ++k) {
    const auto& s = *sets_[k];
    SCOPED_TRACE("set " + std::to_string(k));
    EXPECT_EQ(s.reference_id, k);
    EXPECT_EQ(s.header.frame_id, "world");
    EXPECT_EQ(s.header.stamp, stamps_[2 * k]);
    EXPECT_EQ(s.reference_image.header.stamp, s.header.stamp);
    EXPECT_EQ(s.reference_image.header.frame_id, "cam");
    EXPECT_EQ(s.reference_info.width, 160u);
    // The pixels sent (lossless png when compressed), as rgb8.
    EXPECT_EQ(s.reference_image.encoding, "rgb8");
    EXPECT_EQ(s.reference_image.data, umvs_test::make_image(160, 128, s.reference_image.header).data);
    EXPECT_NEAR(s.reference_pose.position.x, 0.102 * k, 1e-9);
    ASSERT_EQ(s.source_ids.size(), 2u);
    ASSERT_EQ(s.source_images.size(), 2u);
    ASSERT_EQ(s.source_infos.size(), 2u);
    ASSERT_EQ(s.source_poses.size(), 2u);
    for (size_t j = 0; j < 2; ++j) {
      EXPECT_NE(s.source_ids[j], s.reference_id);
      EXPECT_LE(s.source_ids[j], std::max(s.reference_id + 1, 2u)) << "a source from after the set went out";
      // The pose sent with a source is the pose of that keyframe.
      EXPECT_NEAR(s.source_poses[j].position.x, 0.102 * s.source_ids[j], 1e-9);
      EXPECT_EQ(s.source_images[j].header.stamp, stamps_[2 * s.source_ids[j]]);
    }
    EXPECT_NE(s.source_ids[0], s.source_ids[1]);
    EXPECT_FLOAT_EQ(s.depth_min, 1.0f);
    EXPECT_FLOAT_EQ(s.depth_max, 4.0f);
  }
  // The last reference (keyframe 4, x = 0.408) has keyframes 0..3 and 5: at 2.5 m depth the
  // nearest ones (3 and 5, 0.102 m away) triangulate at 2.3 degrees, far from the score's
  // 5 degree optimum, so neither is chosen.
  const auto& last = *sets_.back();
  EXPECT_EQ(last.reference_id, 4u);
  for (const uint32_t id : last.source_ids) {
    EXPECT_NE(id, 3u);
    EXPECT_NE(id, 5u);
  }
  EXPECT_FALSE(log.contains("keyframe_selector:")) << log.all();
}

TEST_F(KeyframeSelectorTest, BadInputIsLoggedAndSkipped) {
  umvs_test::RosoutCapture log(nh_);
  ros::WallDuration(0.3).sleep();
  // Far from the previous test's keyframes, so every good frame here is a keyframe.
  sendFrame(umvs_test::make_pose({5.0, 0, 0}), "cam", "32FC1");
  EXPECT_TRUE(log.wait_for("image encoding '32FC1' is not supported", 5.0)) << log.all();

  sendFrame(umvs_test::make_pose({5.0, 0, 0}), "cam", "rgb8", /*distorted=*/true);
  EXPECT_TRUE(log.wait_for("non-zero distortion coefficients", 5.0)) << log.all();

  // A camera frame nobody publishes a transform for.
  {
    const ros::Time stamp = ros::Time::now();
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = "cam_without_tf";
    info_pub_.publish(umvs_test::make_info(160, 128, 120.0, header));
    image_pub_.publish(umvs_test::make_image(160, 128, header));
  }
  EXPECT_TRUE(log.wait_for("no transform world -> 'cam_without_tf'", 5.0)) << log.all();

  ros::WallDuration(2.2).sleep();  // warnings of one kind are throttled to one per 2 s
  // A NaN pose: tf2 refuses to store it, so the node sees no pose for that frame and skips it.
  geometry_msgs::Pose nan_pose = umvs_test::make_pose({5.0, 0, 0});
  nan_pose.position.y = std::nan("");
  sendFrame(nan_pose, "cam_nan");
  EXPECT_TRUE(log.wait_for("'cam_nan'", 5.0)) << log.all();

  // Still working: good keyframes give sets again (the bad frames added no keyframes); the one at
  // x = 5.3 goes out when the next keyframe came.
  for (int i = 0; i < 4; ++i) sendFrame(umvs_test::make_pose({5.0 + 0.15 * i, 0, 0}));
  ASSERT_TRUE(wait_for([&] { return !sets_.empty() && std::abs(sets_.back()->reference_pose.position.x - 5.3) < 1e-9; },
                       10.0)) << log.all();
}

TEST_F(KeyframeSelectorTest, ACameraThatStopsGetsTheSetOfWhereItStands) {
  // Far from the earlier tests' keyframes: four keyframes 0.2 m apart, then the camera stands
  // still and keeps sending frames. The last keyframe has no newer one to wait for (lookahead 1);
  // the frames' stamps release it max_wait_s (2 s, the default) after it was taken, with the
  // keyframes before it as neighbours.
  for (int i = 0; i < 4; ++i) sendFrame(umvs_test::make_pose({20.0 + 0.2 * i, 0, 0}));
  const ros::Time last_keyframe = stamps_.back();
  auto last_sent = [&] {
    for (const auto& s : sets_) {
      if (std::abs(s->reference_pose.position.x - 20.6) < 1e-9) return s;
    }
    return unsup_mvs::KeyframeSetConstPtr();
  };
  ASSERT_TRUE(wait_for([&] { return !sets_.empty() && std::abs(sets_.back()->reference_pose.position.x - 20.4) < 1e-9; },
                       10.0)) << "the keyframe before the last one goes out when the last one comes";
  const geometry_msgs::Pose standing = umvs_test::make_pose({20.6, 0, 0});
  // Frames stamped less than 2 s after the last keyframe cannot release it.
  while ((ros::Time::now() - last_keyframe).toSec() < 1.5) sendFrame(standing);
  EXPECT_FALSE(last_sent()) << "sent before max_wait_s";
  // The camera goes on sending frames where it stands, as a real one does, until the set comes.
  // However slowly the frames go out (a loaded machine), one stamped 2 s after the keyframe
  // comes, and the set cannot come before it was sent.
  const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(15.0);
  while (!last_sent() && ros::WallTime::now() < give_up) sendFrame(standing);
  ASSERT_TRUE(last_sent() != nullptr) << "the camera stopped and got no depth";
  EXPECT_GE((stamps_.back() - last_keyframe).toSec(), 2.0) << "sent before a frame stamped max_wait_s later";
  const auto& set = *last_sent();
  EXPECT_EQ(set.header.stamp, last_keyframe);
  ASSERT_EQ(set.source_ids.size(), 2u);
  for (size_t j = 0; j < 2; ++j) {
    EXPECT_LT(set.source_ids[j], set.reference_id);
    EXPECT_GE(set.source_poses[j].position.x, 20.0 - 1e-9);
    EXPECT_LT(set.source_poses[j].position.x, 20.6 - 1e-9);
  }
}

TEST_F(KeyframeSelectorTest, AtTheEndOfALogFlushSendsTheLastKeyframe) {
  // Three keyframes 0.2 m apart and no frame after them: the last one waits for a newer keyframe
  // (lookahead 1) until ~flush sends it with the neighbours before it.
  for (int i = 0; i < 3; ++i) sendFrame(umvs_test::make_pose({30.0 + 0.2 * i, 0, 0}));
  auto sent_at = [&](double x) {
    for (const auto& s : sets_) {
      if (std::abs(s->reference_pose.position.x - x) < 1e-9) return s;
    }
    return unsup_mvs::KeyframeSetConstPtr();
  };
  ASSERT_TRUE(wait_for([&] { return sent_at(30.2) != nullptr; }, 10.0)) << "the keyframes before the last one";
  EXPECT_FALSE(sent_at(30.4));
  std_srvs::Trigger flush;
  ASSERT_TRUE(ros::service::call("/keyframe_selector/flush", flush));
  EXPECT_TRUE(flush.response.success);
  EXPECT_EQ(flush.response.message, "sent 1 keyframe set(s); 0 keyframe(s) still wait for neighbours");
  ASSERT_TRUE(wait_for([&] { return sent_at(30.4) != nullptr; }, 10.0));
  EXPECT_EQ(sent_at(30.4)->header.stamp, stamps_.back());
  for (const uint32_t id : sent_at(30.4)->source_ids) EXPECT_LT(id, sent_at(30.4)->reference_id);
  // Nothing waits any more.
  ASSERT_TRUE(ros::service::call("/keyframe_selector/flush", flush));
  EXPECT_EQ(flush.response.message, "sent 0 keyframe set(s); 0 keyframe(s) still wait for neighbours");
}

}  // namespace
