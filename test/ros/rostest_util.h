// Helpers for the rostest executables: waiting on conditions while spinning, capturing the nodes'
// log lines from /rosout, synthetic cameras and images.
#pragma once

#include <gtest/gtest.h>
#include <geometry_msgs/Pose.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <deque>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>

#include "../scratch_dirs.h"

namespace umvs_test {

// Spins until `done` or `timeout` seconds of wall time passed. Returns `done()`.
inline bool wait_for(const std::function<bool()>& done, double timeout) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout);
  while (ros::ok() && !done() && ros::WallTime::now() < end) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  return done();
}

// Keeps the text of every /rosout message at WARN or above.
class RosoutCapture {
 public:
  explicit RosoutCapture(ros::NodeHandle& nh) {
    sub_ = nh.subscribe("/rosout", 100, &RosoutCapture::on, this);
    umvs_test::wait_for([&] { return sub_.getNumPublishers() > 1; }, 5.0);  // the nodes under test connected
    ros::WallDuration(0.2).sleep();
  }
  bool contains(const std::string& text) const {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& l : lines_) {
      if (l.find(text) != std::string::npos) return true;
    }
    return false;
  }
  bool wait_for(const std::string& text, double timeout) {
    return umvs_test::wait_for([&] { return contains(text); }, timeout);
  }
  std::string all() const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::string s;
    for (const auto& l : lines_) s += l + "\n";
    return s;
  }

 private:
  void on(const rosgraph_msgs::Log::ConstPtr& m) {
    if (m->level < rosgraph_msgs::Log::WARN) return;
    std::lock_guard<std::mutex> lock(mutex_);
    lines_.push_back(m->name + ": " + m->msg);
  }
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::deque<std::string> lines_;
};

// Publishes `msg` every `period` s until the log shows `text`: a node throttles its errors of one
// kind, so one bad message right after another may go unreported. Returns whether it showed.
template <class Msg>
bool publish_until_logged(ros::Publisher& pub, const Msg& msg, RosoutCapture& log, const std::string& text,
                          double timeout, double period = 0.5) {
  ros::WallTime next;
  return wait_for([&] {
    if (ros::WallTime::now() >= next) {
      pub.publish(msg);
      next = ros::WallTime::now() + ros::WallDuration(period);
    }
    return log.contains(text);
  }, timeout);
}

// Folder of this executable (devel/lib/unsup_mvs), where the `umvs` tool is too.
inline std::string bin_dir() { return std::filesystem::read_symlink("/proc/self/exe").parent_path().string(); }

// A fresh, empty temporary folder, removed when the test process exits (../scratch_dirs.h).
inline std::string temp_dir(const std::string& name) { return umvs_scratch::scratch_dir("umvs_rostest_", name); }

// An undistorted camera_info of width x height with focal length f and the principal point in the middle.
inline sensor_msgs::CameraInfo make_info(int width, int height, double f, const std_msgs::Header& header) {
  sensor_msgs::CameraInfo info;
  info.header = header;
  info.width = width;
  info.height = height;
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  info.K = {f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {f, 0, (width - 1) / 2.0, 0, 0, f, (height - 1) / 2.0, 0, 0, 0, 1, 0};
  return info;
}

// A textured rgb8 image (deterministic pattern, shifted by `shift` pixels).
inline sensor_msgs::Image make_image(int width, int height, const std_msgs::Header& header, int shift = 0,
                                     const std::string& encoding = "rgb8") {
  sensor_msgs::Image img;
  img.header = header;
  img.width = width;
  img.height = height;
  img.encoding = encoding;
  const int channels = encoding == "rgb8" || encoding == "bgr8" ? 3 : (encoding == "32FC1" ? 4 : 1);
  img.step = width * channels;
  img.data.resize(static_cast<size_t>(img.step) * height);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < static_cast<int>(img.step); ++x) {
      img.data[y * img.step + x] = static_cast<uint8_t>(((x / channels + shift) * 37 + y * 91 + (x % channels) * 60) % 251);
    }
  }
  return img;
}

// Pose of a camera at `center` looking along world +z (identity rotation) turned by yaw_deg about its y axis.
inline geometry_msgs::Pose make_pose(const Eigen::Vector3d& center, double yaw_deg = 0.0) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  geometry_msgs::Pose p;
  p.position.x = center.x();
  p.position.y = center.y();
  p.position.z = center.z();
  p.orientation.w = q.w();
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  return p;
}

}  // namespace umvs_test
