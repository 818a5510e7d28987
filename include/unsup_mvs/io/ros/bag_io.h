// Robot logs as rosbags (rosbag_storage C++ API, no master needed): posed, calibrated images
// written by `umvs bag` and read back by training and tests.
//
// A log holds sensor_msgs/Image (rgb8), sensor_msgs/CameraInfo on its own topic and the camera
// pose as tf2_msgs/TFMessage on /tf (world_frame -> camera_frame, the camera's optical frame,
// REP 103: x right, y down, z forward), all stamped with the image stamp.
#pragma once

#include <torch/types.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace rosbag {
class Bag;
}

namespace umvs {

struct BagTopics {
  std::string image = "/camera/image_rect_color";
  std::string camera_info = "/camera/camera_info";
  std::string world_frame = "world";
  std::string camera_frame = "camera_optical_frame";  // used when writing, and when an image has no frame_id
  // Optional ground truth: sensor_msgs/Image 32FC1 z-depth in metres (0 = unknown), registered to
  // the image and stamped like it. "" = none (read: ignored; write: not written).
  std::string depth;
};

// Writes a log. The bag is written to a temporary file beside `path` and renamed by close(), so
// an interrupted run never leaves (or overwrites with) a truncated bag.
class BagWriter {
 public:
  BagWriter(const std::string& path, BagTopics topics = {});
  ~BagWriter();  // without close(): the temporary file is removed, `path` untouched
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  // Image, CameraInfo and /tf at frame.stamp (> 0). Throws std::invalid_argument for an invalid
  // camera or an image that does not match it.
  void write(const PosedImage& frame);
  void close();
  size_t frames() const { return frames_; }

 private:
  std::string path_, tmp_path_;
  BagTopics topics_;
  std::unique_ptr<rosbag::Bag> bag_;
  size_t frames_ = 0;
};

struct BagReadStats {
  size_t images = 0;          // image messages on the topic
  size_t used = 0;            // delivered to the callback
  size_t without_info = 0;    // no CameraInfo on the info topic at all
  size_t without_pose = 0;    // no transform world_frame -> camera at the image stamp
  size_t invalid = 0;         // unsupported encoding, bad calibration, NaN pose...
  size_t with_depth = 0;      // delivered images that came with a depth map (topics.depth)
  std::string first_error;    // the first of those problems, for the user
};

// Calls `on_image` for every image that has a CameraInfo (the latest at or before its stamp) and a
// pose (tf at the image stamp, interpolated); images without them are counted in `stats` and
// skipped. `rectified` as in camera_from_info. `on_image` returns false to stop early. Throws
// std::runtime_error naming the file when the bag cannot be opened or read.
BagReadStats for_each_posed_image(const std::string& path, const BagTopics& topics, bool rectified,
                                  const std::function<bool(const PosedImage&)>& on_image);

// All posed images of a bag in memory.
std::vector<PosedImage> read_posed_images(const std::string& path, const BagTopics& topics = {},
                                          bool rectified = true, BagReadStats* stats = nullptr);

}  // namespace umvs
