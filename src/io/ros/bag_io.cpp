#include "unsup_mvs/io/ros/bag_io.h"

#include <boost/make_shared.hpp>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2/buffer_core.h>
#include <tf2/exceptions.h>
#include <tf2_msgs/TFMessage.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <map>
#include <memory>
#include <stdexcept>

#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

BagWriter::BagWriter(const std::string& path, BagTopics topics) : path_(path), topics_(std::move(topics)) {
  // An exclusively created, unpredictable temporary name (never a link planted in advance),
  // which rosbag then reopens by name.
  int fd = -1;
  tmp_path_ = create_temp_file_beside(path, &fd);
  ::close(fd);
  bag_ = std::make_unique<rosbag::Bag>();
  try {
    bag_->open(tmp_path_, rosbag::bagmode::Write);
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp_path_, ec);
    throw std::runtime_error("cannot write bag " + path + ": " + e.what());
  }
}

BagWriter::~BagWriter() {
  if (bag_) {
    try {
      bag_->close();
    } catch (...) {
    }
    std::error_code ec;
    std::filesystem::remove(tmp_path_, ec);
  }
}

void BagWriter::write(const PosedImage& frame) {
  if (!bag_) throw std::runtime_error("BagWriter: already closed");
  if (!(frame.stamp > 0) || !std::isfinite(frame.stamp)) throw std::invalid_argument("frame stamp must be > 0");
  frame.camera.validate("frame " + std::to_string(frames_));
  if (frame.image.dim() != 3 || frame.image.size(0) != frame.camera.height || frame.image.size(1) != frame.camera.width) {
    throw std::invalid_argument("frame " + std::to_string(frames_) + ": image size does not match its camera");
  }
  const ros::Time t(frame.stamp);
  std_msgs::Header header;
  header.stamp = t;
  header.frame_id = topics_.camera_frame;
  header.seq = static_cast<uint32_t>(frames_);

  geometry_msgs::TransformStamped tf;
  tf.header.stamp = t;
  tf.header.frame_id = topics_.world_frame;
  tf.child_frame_id = topics_.camera_frame;
  tf.transform = matrix_to_transform(frame.camera.T_world_cam());
  tf2_msgs::TFMessage tfm;
  tfm.transforms.push_back(tf);

  bag_->write("/tf", t, tfm);
  bag_->write(topics_.camera_info, t, camera_info_from_camera(frame.camera, header));
  bag_->write(topics_.image, t, rgb8_to_image_msg(frame.image, header));
  if (!topics_.depth.empty() && frame.depth.defined()) {
    if (frame.depth.dim() != 2 || frame.depth.size(0) != frame.camera.height || frame.depth.size(1) != frame.camera.width) {
      throw std::invalid_argument("frame " + std::to_string(frames_) + ": depth size does not match its camera");
    }
    bag_->write(topics_.depth, t, float_to_image_msg(frame.depth.to(torch::kFloat32).contiguous(), header));
  }
  ++frames_;
}

void BagWriter::close() {
  if (!bag_) return;
  bag_->close();
  bag_.reset();
  std::error_code ec;
  std::filesystem::rename(tmp_path_, path_, ec);
  if (ec) {
    std::filesystem::remove(tmp_path_, ec);
    throw std::runtime_error("cannot move the finished bag to " + path_);
  }
}

BagReadStats for_each_posed_image(const std::string& path, const BagTopics& topics, bool rectified,
                                  const std::function<bool(const PosedImage&)>& on_image) {
  BagReadStats stats;
  auto note = [&](const std::string& what) {
    if (stats.first_error.empty()) stats.first_error = what;
  };
  try {
    rosbag::Bag bag(path, rosbag::bagmode::Read);
    // Pass 1: every transform, so that a pose can be interpolated at any image stamp.
    rosbag::View tf_view(bag, rosbag::TopicQuery(std::vector<std::string>{"/tf", "/tf_static"}));
    // The buffer keeps the whole log. (An empty view's begin is after its end: no subtraction of
    // ros::Time then, it throws "Duration is out of dual 32-bit range".)
    const bool has_tf = tf_view.size() > 0;
    const double span = has_tf ? std::max(1.0, tf_view.getEndTime().toSec() - tf_view.getBeginTime().toSec() + 1.0) : 1.0;
    tf2::BufferCore tf_buffer{ros::Duration(std::min(span, 2147483647.0))};
    for (const rosbag::MessageInstance& m : tf_view) {
      auto msg = m.instantiate<tf2_msgs::TFMessage>();
      if (!msg) continue;
      const bool is_static = m.getTopic() == "/tf_static";
      for (const auto& t : msg->transforms) {
        try {
          tf_buffer.setTransform(t, "bag", is_static);
        } catch (const std::exception& e) {
          note(std::string("bad transform: ") + e.what());
        }
      }
    }
    // Camera infos by stamp: an image uses the latest one at or before its stamp (messages of one
    // stamp may be stored in any order), or the first one when it precedes them all.
    std::map<ros::Time, sensor_msgs::CameraInfo::ConstPtr> infos;
    rosbag::View info_view(bag, rosbag::TopicQuery(topics.camera_info));
    for (const rosbag::MessageInstance& m : info_view) {
      if (auto i = m.instantiate<sensor_msgs::CameraInfo>()) infos[i->header.stamp] = i;
    }
    // Depth maps by header stamp; only their place in the bag is kept (a map is read again when
    // an image of its stamp is used), so memory does not grow with the log.
    std::map<ros::Time, rosbag::MessageInstance> depths;
    std::unique_ptr<rosbag::View> depth_view;
    if (!topics.depth.empty()) {
      depth_view = std::make_unique<rosbag::View>(bag, rosbag::TopicQuery(topics.depth));
      for (const rosbag::MessageInstance& m : *depth_view) {
        if (auto d = m.instantiate<sensor_msgs::Image>()) depths.emplace(d->header.stamp, m);
      }
    }
    // Pass 2: images.
    rosbag::View view(bag, rosbag::TopicQuery(topics.image));
    for (const rosbag::MessageInstance& m : view) {
      sensor_msgs::Image::ConstPtr img = m.instantiate<sensor_msgs::Image>();
      if (!img) {
        // jpeg/png (a camera driver's or image_transport's `compressed` topic): decoded here.
        const auto compressed = m.instantiate<sensor_msgs::CompressedImage>();
        if (!compressed) continue;
        try {
          img = boost::make_shared<sensor_msgs::Image>(compressed_to_image_msg(*compressed, kMaxImagePixels));
        } catch (const std::invalid_argument& e) {
          ++stats.images;
          ++stats.invalid;
          note("image at " + std::to_string(compressed->header.stamp.toSec()) + ": " + e.what());
          continue;
        }
      }
      ++stats.images;
      if (infos.empty()) {
        ++stats.without_info;
        note("no CameraInfo on " + topics.camera_info);
        continue;
      }
      auto it = infos.upper_bound(img->header.stamp);
      const sensor_msgs::CameraInfo::ConstPtr info = it == infos.begin() ? it->second : std::prev(it)->second;
      const std::string frame = img->header.frame_id.empty() ? topics.camera_frame : img->header.frame_id;
      const double stamp = img->header.stamp.toSec();
      Eigen::Matrix4d T_world_camera;
      if (!has_tf) {
        ++stats.without_pose;
        note("no transform found from '" + topics.world_frame + "' to the camera frame '" + frame +
             "': the bag has no messages on /tf or /tf_static");
        continue;
      }
      try {
        T_world_camera = transform_to_matrix(tf_buffer.lookupTransform(topics.world_frame, frame, img->header.stamp).transform);
      } catch (const tf2::TransformException& e) {
        ++stats.without_pose;
        note("no transform found from '" + topics.world_frame + "' to the camera frame '" + frame + "' at " +
             std::to_string(stamp) + ": " + e.what());
        continue;
      } catch (const std::invalid_argument& e) {
        ++stats.invalid;
        note(std::string("bad pose: ") + e.what());
        continue;
      }
      PosedImage out;
      try {
        out = posed_image_from_msgs(*img, *info, T_world_camera, rectified);
      } catch (const std::invalid_argument& e) {
        ++stats.invalid;
        note("image at " + std::to_string(stamp) + ": " + e.what());
        continue;
      }
      const auto d = depths.find(img->header.stamp);
      if (d != depths.end()) {
        if (auto depth_msg = d->second.instantiate<sensor_msgs::Image>()) {
          try {
            out.depth = image_msg_to_float(*depth_msg);
            if (out.depth.size(0) != out.camera.height || out.depth.size(1) != out.camera.width) {
              throw std::invalid_argument("depth map size differs from the image's");
            }
            ++stats.with_depth;
          } catch (const std::invalid_argument& e) {
            out.depth = torch::Tensor();
            note(std::string("depth on ") + topics.depth + " ignored: " + e.what());
          }
        }
      }
      ++stats.used;
      if (!on_image(out)) break;
    }
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error("cannot read bag " + path + ": " + e.what());
  }
  return stats;
}

std::vector<PosedImage> read_posed_images(const std::string& path, const BagTopics& topics, bool rectified,
                                          BagReadStats* stats) {
  std::vector<PosedImage> frames;
  const BagReadStats s = for_each_posed_image(path, topics, rectified, [&](const PosedImage& f) {
    frames.push_back(f);
    return true;
  });
  if (stats) *stats = s;
  return frames;
}

}  // namespace umvs
