// rostest: one bag, fed live through the keyframe_selector node and read
// offline by read_bag_keyframes (what `umvs train --bag` and the trainer node use), gives the
// same keyframes, in the same order, with the same intrinsics. The camera has distinct K and P
// (and distortion), so reading the wrong one of them, or a different ~rectified, shows.
//
// Both sides take their settings from the pipeline's config/keyframe_selector.yaml: the node
// from its private namespace, this test from ~keyframes/ (as pipeline.launch sets up the
// trainer), with rectified set explicitly in selector_bag_parity.test.
#include <geometry_msgs/PoseArray.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2_msgs/TFMessage.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include "rostest_util.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/io/ros/bag_training_data.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/ros/params.h"

namespace {

using umvs_test::wait_for;

constexpr int kWidth = 64, kHeight = 48, kFrames = 28;
const char* const kCameraFrame = "camera_optical_frame";

// Raw camera: K with distortion; P of the rectified image differs in every intrinsic.
sensor_msgs::CameraInfo make_raw_info(const std_msgs::Header& header) {
  sensor_msgs::CameraInfo info;
  info.header = header;
  info.width = kWidth;
  info.height = kHeight;
  info.distortion_model = "plumb_bob";
  info.D = {-0.12, 0.03, 0.001, -0.002, 0.0};
  info.K = {200.0, 0, 31.5, 0, 202.0, 23.5, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {180.25, 0, 30.75, 0, 0, 185.5, 22.125, 0, 0, 0, 1, 0};
  return info;
}

// The trajectory: mostly along x in steps of 0.04, 0.04, 0.04, 0.17 m (so some frames are
// keyframes and some not), a slow yaw wobble, and a turn on the spot (4 deg per frame, frames
// 13-16) that makes a keyframe by rotation. Every keyframe decision is at least 0.02 m / 0.4 deg
// away from the thresholds of config/keyframe_selector.yaml (0.10 m, 10 deg).
std::vector<geometry_msgs::Pose> trajectory() {
  std::vector<geometry_msgs::Pose> poses;
  double x = 0, turn = 0;
  for (int i = 0; i < kFrames; ++i) {
    if (i > 0) {
      if (i >= 13 && i <= 16) {
        turn += 4.0;
      } else {
        x += (i % 4 == 3) ? 0.17 : 0.04;
      }
    }
    poses.push_back(umvs_test::make_pose({x, 0.005 * std::sin(0.7 * i), 0.01 * std::cos(0.5 * i)},
                                         turn + 3.0 * std::sin(0.3 * i)));
  }
  return poses;
}

ros::Time stamp_of(int i) { return ros::Time(1000.0 + 0.1 * i); }

// Writes the log as a camera driver + localisation would record it: /tf, camera_info and image
// at each stamp.
void write_bag(const std::string& path, const std::string& world_frame, const std::string& image_topic,
               const std::string& info_topic) {
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  const auto poses = trajectory();
  for (int i = 0; i < kFrames; ++i) {
    std_msgs::Header header;
    header.stamp = stamp_of(i);
    header.frame_id = kCameraFrame;
    header.seq = static_cast<uint32_t>(i);
    geometry_msgs::TransformStamped tf;
    tf.header.stamp = header.stamp;
    tf.header.frame_id = world_frame;
    tf.child_frame_id = kCameraFrame;
    tf.transform.translation.x = poses[i].position.x;
    tf.transform.translation.y = poses[i].position.y;
    tf.transform.translation.z = poses[i].position.z;
    tf.transform.rotation = poses[i].orientation;
    tf2_msgs::TFMessage tfm;
    tfm.transforms.push_back(tf);
    bag.write("/tf", header.stamp, tfm);
    bag.write(info_topic, header.stamp, make_raw_info(header));
    bag.write(image_topic, header.stamp, umvs_test::make_image(kWidth, kHeight, header, 3 * i));
  }
  bag.close();
}

struct Frame {
  tf2_msgs::TFMessage::ConstPtr tf;
  sensor_msgs::CameraInfo::ConstPtr info;
  sensor_msgs::Image::ConstPtr image;
};

// The bag's messages grouped by their time, in time order.
std::map<ros::Time, Frame> read_frames(const std::string& path, const std::string& image_topic,
                                       const std::string& info_topic) {
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  rosbag::View view(bag);
  std::map<ros::Time, Frame> frames;
  for (const rosbag::MessageInstance& m : view) {
    Frame& f = frames[m.getTime()];
    if (m.getTopic() == "/tf") {
      f.tf = m.instantiate<tf2_msgs::TFMessage>();
    } else if (m.getTopic() == info_topic) {
      f.info = m.instantiate<sensor_msgs::CameraInfo>();
    } else if (m.getTopic() == image_topic) {
      f.image = m.instantiate<sensor_msgs::Image>();
    }
  }
  return frames;
}

struct Intrinsics {
  double fx, fy, cx, cy;
};
Intrinsics intrinsics_of(const umvs::Camera& c) { return {c.K(0, 0), c.K(1, 1), c.K(0, 2), c.K(1, 2)}; }

void expect_same_intrinsics(const Intrinsics& live, const Intrinsics& offline, const std::string& what) {
  EXPECT_NEAR(live.fx, offline.fx, 1e-6) << what;
  EXPECT_NEAR(live.fy, offline.fy, 1e-6) << what;
  EXPECT_NEAR(live.cx, offline.cx, 1e-6) << what;
  EXPECT_NEAR(live.cy, offline.cy, 1e-6) << what;
}

std::string stamps_text(const std::vector<ros::Time>& stamps) {
  std::ostringstream s;
  for (const auto& t : stamps) s << " " << (t.toSec() - 1000.0) * 10;  // frame index
  return s.str();
}

TEST(SelectorBagParity, SameKeyframesAndIntrinsicsLiveAndOffline) {
  ros::NodeHandle nh, pnh("~");
  // The settings, read as the trainer node reads them (its ~keyframes/ and topic parameters).
  const umvs::KeyframeStreamConfig stream = umvs_ros::keyframe_stream_config_from_ros(ros::NodeHandle(pnh, "keyframes"));
  const std::string world_frame = pnh.param<std::string>("world_frame", "world");
  const std::string image_topic = pnh.param<std::string>("image_topic", "/camera/image_rect_color");
  const std::string info_topic = pnh.param<std::string>("camera_info_topic", "/camera/camera_info");
  // The node was given the same: one YAML, rectified set explicitly for both.
  bool node_rectified = !stream.rectified;
  ASSERT_TRUE(nh.getParam("/keyframe_selector/rectified", node_rectified));
  ASSERT_EQ(node_rectified, stream.rectified);
  ASSERT_TRUE(stream.rectified) << "the .test sets rectified:=true";

  const std::string dir = umvs_test::temp_dir("selector_bag_parity");
  const std::string bag_path = dir + "/log.bag";
  write_bag(bag_path, world_frame, image_topic, info_topic);

  // Offline: what `umvs train --bag` reads (keyframe_stream_train_args carries `stream` to it).
  umvs::BagDataConfig config;
  static_cast<umvs::KeyframeStreamConfig&>(config) = stream;
  config.topics.image = image_topic;
  config.topics.camera_info = info_topic;
  config.topics.world_frame = world_frame;
  std::ostringstream log;
  const std::vector<umvs::BagKeyframe> offline = umvs::read_bag_keyframes({bag_path}, config, &log);
  std::vector<ros::Time> offline_stamps;
  for (const auto& k : offline) offline_stamps.push_back(ros::Time(k.image.stamp));
  const std::set<ros::Time> offline_set(offline_stamps.begin(), offline_stamps.end());
  ASSERT_GE(offline.size(), 8u) << log.str();
  ASSERT_LT(offline.size(), static_cast<size_t>(kFrames)) << "some frames must not be keyframes";
  // Intrinsics from P (rectified), not from K.
  EXPECT_NEAR(offline[0].image.camera.K(0, 0), 180.25, 1e-9);
  EXPECT_NEAR(offline[0].image.camera.K(1, 1), 185.5, 1e-9);

  // Live: every keyframe shows as a keyframe_poses message stamped with it; sets on keyframes.
  std::vector<ros::Time> live_stamps;
  std::vector<unsup_mvs::KeyframeSetConstPtr> sets;
  auto poses_sub = nh.subscribe<geometry_msgs::PoseArray>(
      "/keyframe_poses", 100, [&](const geometry_msgs::PoseArrayConstPtr& m) { live_stamps.push_back(m->header.stamp); });
  auto sets_sub = nh.subscribe<unsup_mvs::KeyframeSet>(
      "/keyframes", 100, [&](const unsup_mvs::KeyframeSetConstPtr& m) { sets.push_back(m); });
  auto image_pub = nh.advertise<sensor_msgs::Image>(image_topic, kFrames);
  auto info_pub = nh.advertise<sensor_msgs::CameraInfo>(info_topic, kFrames);
  auto tf_pub = nh.advertise<tf2_msgs::TFMessage>("/tf", kFrames);
  ASSERT_TRUE(wait_for([&] { return image_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
                                    tf_pub.getNumSubscribers() > 0 && poses_sub.getNumPublishers() > 0 &&
                                    sets_sub.getNumPublishers() > 0; }, 30.0))
      << "keyframe_selector did not connect";

  // Replay the bag in order, frame by frame (/tf, then camera_info, then image). After a frame
  // that the offline reader keeps, wait until the node has published it: the node processes its
  // input in order, so at most the frames since the last keyframe (5 here, under its queue of
  // 10) are ever in flight and none is dropped. A keyframe the node makes and the offline reader
  // does not shows in live_stamps; one the node does not make ends the wait with a failure.
  const auto frames = read_frames(bag_path, image_topic, info_topic);
  ASSERT_EQ(frames.size(), static_cast<size_t>(kFrames));
  for (const auto& [t, f] : frames) {
    ASSERT_TRUE(f.tf && f.info && f.image);
    tf_pub.publish(*f.tf);
    info_pub.publish(*f.info);
    image_pub.publish(*f.image);
    if (offline_set.count(t)) {
      ASSERT_TRUE(wait_for([&, t = t] { return std::find(live_stamps.begin(), live_stamps.end(), t) != live_stamps.end(); },
                           20.0))
          << "the node did not make frame " << (t.toSec() - 1000.0) * 10 << " a keyframe; live:"
          << stamps_text(live_stamps) << "; offline:" << stamps_text(offline_stamps);
    }
  }
  // The last frame is a keyframe (offline), and the node processes in order: all frames are in.
  ASSERT_EQ(offline_stamps.back(), frames.rbegin()->first);
  // The node publishes a keyframe's set after its poses, on another connection: give the last
  // set (if the last keyframe has enough neighbours for one) the chance to arrive. Which sets
  // arrived does not change what is checked about each.
  wait_for([&] { return !sets.empty() && sets.back()->header.stamp == offline_stamps.back(); }, 5.0);

  EXPECT_EQ(live_stamps, offline_stamps) << "live:" << stamps_text(live_stamps)
                                         << "\noffline:" << stamps_text(offline_stamps);

  // The keyframe sets: references and sources are offline keyframes with the same ids (both
  // number keyframes from 0 in order) and the same intrinsics, read from the CameraInfo the node
  // sends as the inference node reads it (with the same ~rectified).
  ASSERT_GE(sets.size(), 3u) << "keyframe sets published";
  std::map<ros::Time, size_t> offline_index;
  for (size_t i = 0; i < offline.size(); ++i) offline_index[offline_stamps[i]] = i;
  for (const auto& s : sets) {
    const auto it = offline_index.find(s->header.stamp);
    ASSERT_NE(it, offline_index.end()) << "set at frame " << (s->header.stamp.toSec() - 1000.0) * 10;
    EXPECT_EQ(s->reference_id, it->second);
    EXPECT_EQ(s->reference_image.header.stamp, s->header.stamp);
    const Intrinsics offline_ref = intrinsics_of(offline[it->second].image.camera);
    expect_same_intrinsics(intrinsics_of(umvs::camera_from_info(s->reference_info, node_rectified)), offline_ref,
                           "reference " + std::to_string(s->reference_id));
    EXPECT_NEAR(offline_ref.fx, 180.25, 1e-9);
    EXPECT_NEAR(offline_ref.fy, 185.5, 1e-9);
    EXPECT_NEAR(offline_ref.cx, 30.75, 1e-9);
    EXPECT_NEAR(offline_ref.cy, 22.125, 1e-9);
    ASSERT_EQ(s->source_ids.size(), s->source_infos.size());
    for (size_t j = 0; j < s->source_ids.size(); ++j) {
      const uint32_t id = s->source_ids[j];
      ASSERT_LT(id, offline.size());
      EXPECT_EQ(s->source_images[j].header.stamp, offline_stamps[id]) << "source " << id;
      expect_same_intrinsics(intrinsics_of(umvs::camera_from_info(s->source_infos[j], node_rectified)),
                             intrinsics_of(offline[id].image.camera), "source " + std::to_string(id));
    }
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
