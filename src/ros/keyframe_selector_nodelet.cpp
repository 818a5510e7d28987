// keyframe_selector: calibrated, posed images -> KeyframeSet (a reference keyframe + its best
// neighbours) whenever the camera moved enough. The keyframe policy and depth range can be tuned
// live (dynamic_reconfigure, cfg/KeyframeSelector.cfg). See docs/ros.md for topics and parameters.
#include <geometry_msgs/PoseArray.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/pass_through.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <boost/make_shared.hpp>
#include <map>
#include <mutex>

#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSelectorConfig.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/core/depth_range.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/core/view_selection.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/ros/nodelets.h"
#include "unsup_mvs/ros/live_settings.h"
#include "unsup_mvs/ros/params.h"
#include "unsup_mvs/ros/reconfigure.h"

namespace umvs_ros {

class KeyframeSelectorNodelet : public nodelet::Nodelet {
 public:
  ~KeyframeSelectorNodelet() override = default;

 private:
  using ExactPolicy = message_filters::sync_policies::ExactTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;
  using ApproxPolicy = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;

  struct StoredFrame {
    sensor_msgs::ImageConstPtr image;
    sensor_msgs::CameraInfoConstPtr info;
    geometry_msgs::Pose pose;  // T_world_camera
  };

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param<std::string>("world_frame", world_frame_, "world");
    pnh.param("tf_timeout", tf_timeout_, 0.1);
    pnh.param("depth_from_estimates", depth_from_estimates_, true);
    int queue_size = 10;
    pnh.param("queue_size", queue_size, queue_size);
    bool approximate_sync = false;
    pnh.param("approximate_sync", approximate_sync, approximate_sync);
    pnh.param("max_image_pixels", max_image_pixels_, kDefaultMaxImagePixels);
    std::string transport = "raw";
    pnh.param("image_transport", transport, transport);
    try {
      if (max_image_pixels_ < 1) throw std::invalid_argument("max_image_pixels must be >= 1");
      if (transport != "raw" && transport != "compressed") {
        throw std::invalid_argument("image_transport must be 'raw' or 'compressed', got '" + transport + "'");
      }
      stream_ = keyframe_stream_config_from_ros(pnh);
      buffer_ = std::make_unique<umvs::KeyframeBuffer>(stream_.keyframes);
      rectified_ = stream_.rectified;
      depth_range_ = std::make_unique<umvs::DepthRangeTracker>(stream_.depth_min, stream_.depth_max);
      if (queue_size < 1) throw std::invalid_argument("queue_size must be >= 1");
    } catch (const std::exception& e) {
      NODELET_FATAL("keyframe_selector: invalid parameters: %s", e.what());
      throw;
    }

    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    // Sets can go out in bursts (a keyframe that waited for neighbours, then the newest one): room
    // for them towards subscribers in other processes.
    keyframes_pub_ = nh.advertise<unsup_mvs::KeyframeSet>("keyframes", kSetQueue);
    poses_pub_ = nh.advertise<geometry_msgs::PoseArray>("keyframe_poses", 1, true);
    flush_srv_ = pnh.advertiseService("flush", &KeyframeSelectorNodelet::onFlush, this);
    if (depth_from_estimates_) estimate_sub_ = nh.subscribe("depth_estimate", 1, &KeyframeSelectorNodelet::onEstimate, this);

    info_sub_.subscribe(nh, "camera_info", queue_size);
    if (transport == "compressed") {
      // jpeg/png on <image>/compressed, as image_transport's `compressed` transport names it; Debian
      // ships no compressed_image_transport plugin, so the selector decodes them itself (io).
      image_topic_ = nh.resolveName("image") + "/compressed";
      compressed_sub_ = nh.subscribe(image_topic_, queue_size, &KeyframeSelectorNodelet::onCompressedImage, this);
      synchronise(decoded_images_, queue_size, approximate_sync);
    } else {
      it_ = std::make_unique<image_transport::ImageTransport>(nh);
      const image_transport::TransportHints hints("raw", ros::TransportHints(), pnh);
      image_topic_ = nh.resolveName("image");
      image_sub_.subscribe(*it_, "image", queue_size, hints);
      synchronise(image_sub_, queue_size, approximate_sync);
    }
    info_sub_.registerCallback(&KeyframeSelectorNodelet::onAnyInfo, this);
    reconfigure_ = std::make_unique<ReconfigureServer<unsup_mvs::KeyframeSelectorConfig>>(
        pnh, "keyframe_selector", to_reconfigure(stream_),
        [this](const unsup_mvs::KeyframeSelectorConfig& r) { onReconfigure(r); });
    const auto& c = stream_.keyframes;
    NODELET_INFO("keyframe_selector: %s + %s in '%s' (%s sync), keyframe after %.2f m / %.1f deg / pose distance %.2f, "
                 "buffer %d, %d neighbours (lookahead %d keyframes, at most %.1f s), depth %.2f-%.2f m%s",
                 image_topic_.c_str(), info_sub_.getTopic().c_str(), world_frame_.c_str(),
                 approximate_sync ? "approximate" : "exact", c.min_translation, c.min_rotation_deg, c.min_pose_distance,
                 c.buffer_size, c.num_sources, c.lookahead, c.max_wait_s, stream_.depth_min, stream_.depth_max,
                 depth_from_estimates_ ? " (then from depth estimates)" : "");
  }

  // A new keyframe policy or depth range from dynamic_reconfigure: checked as at start-up, used
  // from the next frame. New bounds restart the depth range (until the next depth estimate).
  // Throws std::invalid_argument (naming the parameter) and changes nothing when invalid.
  void onReconfigure(const unsup_mvs::KeyframeSelectorConfig& request) {
    const umvs::KeyframeStreamConfig next = with_reconfigure(stream_, request);
    next.validate();
    std::unique_ptr<umvs::DepthRangeTracker> tracker;
    if (next.depth_min != stream_.depth_min || next.depth_max != stream_.depth_max) {
      tracker = std::make_unique<umvs::DepthRangeTracker>(next.depth_min, next.depth_max);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    for (const int64_t id : buffer_->set_config(next.keyframes)) frames_by_id_.erase(id);
    if (tracker) depth_range_ = std::move(tracker);
    stream_ = next;
  }

  // Images (raw or decoded) paired with their CameraInfo, exactly or approximately by stamp.
  template <typename ImageFilter>
  void synchronise(ImageFilter& images, int queue_size, bool approximate) {
    if (approximate) {
      approx_sync_ = std::make_unique<message_filters::Synchronizer<ApproxPolicy>>(ApproxPolicy(queue_size), images, info_sub_);
      approx_sync_->registerCallback(&KeyframeSelectorNodelet::onImage, this);
    } else {
      exact_sync_ = std::make_unique<message_filters::Synchronizer<ExactPolicy>>(ExactPolicy(queue_size), images, info_sub_);
      exact_sync_->registerCallback(&KeyframeSelectorNodelet::onImage, this);
    }
    // Beside the sync: notice images that have no CameraInfo to pair with (the sync stays silent).
    images.registerCallback(&KeyframeSelectorNodelet::onAnyImage, this);
  }

  void onCompressedImage(const sensor_msgs::CompressedImageConstPtr& msg) {
    sensor_msgs::ImagePtr image;
    try {
      image = boost::make_shared<sensor_msgs::Image>(umvs::compressed_to_image_msg(*msg, static_cast<uint64_t>(max_image_pixels_)));
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: bad image on '%s': %s; frame skipped", image_topic_.c_str(), e.what());
      return;
    }
    decoded_images_.add(image);
  }

  void onAnyInfo(const sensor_msgs::CameraInfoConstPtr&) { last_info_wall_ = ros::WallTime::now().toSec(); }

  void onAnyImage(const sensor_msgs::ImageConstPtr&) {
    const double now = ros::WallTime::now().toSec(), last_info = last_info_wall_;
    double first_image = first_image_wall_;
    if (first_image == 0.0) first_image_wall_ = first_image = now;
    // Quiet for the first seconds: at start the first image may simply come before its CameraInfo.
    if (now - std::max(first_image, last_info) < kInfoSilenceSeconds) return;
    NODELET_WARN_THROTTLE(kInfoSilenceSeconds, "keyframe_selector: images arrive on '%s' but %s on '%s'; nothing is "
                          "processed until image and camera_info arrive together",
                          image_topic_.c_str(),
                          last_info > 0 ? "no CameraInfo came for a while" : "no CameraInfo has come",
                          info_sub_.getTopic().c_str());
  }

  void onImage(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!umvs::is_supported_image_encoding(image->encoding)) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: image encoding '%s' is not supported (use rgb8, bgr8, rgba8, "
                             "bgra8, mono8 or mono16); frame skipped", image->encoding.c_str());
      return;
    }
    try {
      // Here, where images enter: a truncated image kept as a keyframe would spoil every later set.
      umvs::check_image_msg(*image, static_cast<uint64_t>(max_image_pixels_));
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: bad image on '%s': %s; frame skipped", image_topic_.c_str(),
                             e.what());
      return;
    }
    umvs::Camera camera;
    try {
      camera = umvs::camera_from_info(*info, rectified_);
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: bad camera_info: %s; frame skipped", e.what());
      return;
    }
    if (image->width != info->width || image->height != info->height) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: image is %ux%u but camera_info says %ux%u; frame skipped",
                             image->width, image->height, info->width, info->height);
      return;
    }
    const std::string& camera_frame = image->header.frame_id;
    geometry_msgs::TransformStamped tf;
    try {
      tf = lookupCameraTransform(camera_frame, image->header.stamp);
    } catch (const tf2::TransformException& e) {
      NODELET_WARN_THROTTLE(2.0, "keyframe_selector: no transform %s -> '%s' at %.3f: %s; frame skipped",
                            world_frame_.c_str(), camera_frame.c_str(), image->header.stamp.toSec(), e.what());
      return;
    }
    geometry_msgs::Pose pose;  // T_world_camera, forwarded in the keyframe sets
    try {
      const Eigen::Matrix4d T_world_camera = umvs::transform_to_matrix(tf.transform);
      camera.T_cam_world = T_world_camera.inverse();
      camera.validate("camera pose");
      pose = umvs::matrix_to_pose(T_world_camera);
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "keyframe_selector: invalid pose of '%s' in '%s' at %.3f: %s; frame skipped",
                             camera_frame.c_str(), world_frame_.c_str(), image->header.stamp.toSec(), e.what());
      return;
    }
    ++frames_;
    const double stamp = image->header.stamp.toSec();
    if (buffer_->is_keyframe(camera)) {
      int64_t evicted = -1;
      const umvs::Keyframe& ref = buffer_->add(camera, stamp, &evicted);
      frames_by_id_[ref.id] = {image, info, pose};
      if (evicted >= 0) frames_by_id_.erase(evicted);
      publishPoses(image->header.stamp);
    } else if (buffer_->waiting_references() == 0) {
      return;
    }
    // Every frame's stamp is the clock by which a keyframe stops waiting for its lookahead
    // (max_wait_s): a robot that stands still gets the depth of where it stands.
    const umvs::DepthRange range = depth_range_->range();
    std::vector<int64_t> given_up;
    const double score_depth = umvs::view_selection_depth(range.near, range.far);
    for (const auto& ready : buffer_->take_ready_references(score_depth, &given_up, stamp)) {
      publishSet(ready, range.near, range.far);
    }
    for (const int64_t id : given_up) {
      NODELET_DEBUG("keyframe_selector: keyframe %ld found no %d usable neighbours; it is no reference",
                    static_cast<long>(id), buffer_->config().num_sources);
    }
  }

  // The end of a log (no frame comes any more to release the newest keyframe): the keyframes
  // still waiting for their lookahead go out with the neighbours they have.
  // The camera's pose at `stamp`, waiting at most ~tf_timeout seconds of wall time for it: tf2's own
  // timeout counts ROS time, which stops with a replayed log, and the callback would then wait for
  // ever (and with it the flush service). Throws tf2::TransformException when it does not come.
  geometry_msgs::TransformStamped lookupCameraTransform(const std::string& camera_frame, const ros::Time& stamp) {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(tf_timeout_);
    while (!tf_buffer_->canTransform(world_frame_, camera_frame, stamp) && ros::WallTime::now() < deadline && ros::ok()) {
      ros::WallDuration(0.002).sleep();
    }
    return tf_buffer_->lookupTransform(world_frame_, camera_frame, stamp);
  }

  bool onFlush(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const umvs::DepthRange range = depth_range_->range();
    const auto ready = buffer_->take_waiting_references(umvs::view_selection_depth(range.near, range.far));
    for (const auto& r : ready) publishSet(r, range.near, range.far);
    res.success = true;
    res.message = "sent " + std::to_string(ready.size()) + " keyframe set(s); " +
                  std::to_string(buffer_->waiting_references()) + " keyframe(s) still wait for neighbours";
    NODELET_INFO("keyframe_selector: flush: %s", res.message.c_str());
    return true;
  }

  void publishSet(const umvs::ReferenceSources& ready, double near, double far) {
    const StoredFrame& ref = frames_by_id_.at(ready.reference_id);
    unsup_mvs::KeyframeSet set;
    set.header.stamp = ref.image->header.stamp;
    set.header.frame_id = world_frame_;
    set.reference_id = static_cast<uint32_t>(ready.reference_id);
    set.reference_image = *ref.image;
    set.reference_info = *ref.info;
    set.reference_pose = ref.pose;
    for (const auto& s : ready.sources) {
      const StoredFrame& f = frames_by_id_.at(s.id);
      set.source_ids.push_back(static_cast<uint32_t>(s.id));
      set.source_images.push_back(*f.image);
      set.source_infos.push_back(*f.info);
      set.source_poses.push_back(f.pose);
    }
    set.depth_min = static_cast<float>(near);
    set.depth_max = static_cast<float>(far);
    keyframes_pub_.publish(set);
    ++sets_;
    NODELET_INFO_THROTTLE(10.0, "keyframe_selector: %ld frames, %ld keyframe sets; keyframe %ld with %u, %u, depth %.2f-%.2f m",
                          frames_, sets_, static_cast<long>(ready.reference_id), set.source_ids[0],
                          set.source_ids.size() > 1 ? set.source_ids[1] : 0u, near, far);
  }

  // Depth range for the next keyframes from the latest depth estimate (confident pixels only).
  void onEstimate(const unsup_mvs::DepthEstimateConstPtr& msg) {
    try {
      const auto depth = umvs::image_msg_to_float(msg->depth);
      const auto conf = umvs::image_msg_to_float(msg->confidence);
      if (!depth.sizes().equals(conf.sizes())) throw std::invalid_argument("depth and confidence differ in size");
      const auto d = depth.contiguous(), c = conf.contiguous();
      std::vector<float> values = umvs::confident_depths(d.data_ptr<float>(), c.data_ptr<float>(),
                                                         static_cast<size_t>(d.numel()));
      double near = 0, far = 0;
      if (!umvs::depth_range_from_samples(std::move(values), &near, &far)) return;
      std::lock_guard<std::mutex> lock(mutex_);
      depth_range_->update(near, far);  // clamped to the configured bounds
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(10.0, "keyframe_selector: ignoring depth estimate for the depth range: %s", e.what());
    }
  }

  void publishPoses(const ros::Time& stamp) {
    geometry_msgs::PoseArray poses;
    poses.header.stamp = stamp;
    poses.header.frame_id = world_frame_;
    for (const auto& k : buffer_->keyframes()) poses.poses.push_back(frames_by_id_.at(k.id).pose);
    poses_pub_.publish(poses);
  }

  static constexpr double kInfoSilenceSeconds = 3.0;  // images without CameraInfo for this long: warn
  static constexpr uint32_t kSetQueue = 4;            // keyframe sets queued per remote subscriber

  std::string world_frame_;
  double tf_timeout_ = 0.1;
  umvs::KeyframeStreamConfig stream_;  // as started, then as reconfigured (changed only by onReconfigure)
  int max_image_pixels_ = kDefaultMaxImagePixels;
  std::atomic<double> first_image_wall_{0.0}, last_info_wall_{0.0};  // wall seconds, 0 = none yet
  bool rectified_ = false, depth_from_estimates_ = true;
  std::mutex mutex_;
  std::unique_ptr<umvs::KeyframeBuffer> buffer_;
  std::map<int64_t, StoredFrame> frames_by_id_;
  std::unique_ptr<umvs::DepthRangeTracker> depth_range_;  // configured bounds, then from the estimates
  long frames_ = 0, sets_ = 0;

  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::SubscriberFilter image_sub_;                      // image_transport:=raw
  message_filters::PassThrough<sensor_msgs::Image> decoded_images_;  // image_transport:=compressed,
  ros::Subscriber compressed_sub_;                                    // decoded from here
  std::string image_topic_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  std::unique_ptr<message_filters::Synchronizer<ExactPolicy>> exact_sync_;
  std::unique_ptr<message_filters::Synchronizer<ApproxPolicy>> approx_sync_;
  ros::Publisher keyframes_pub_, poses_pub_;
  ros::ServiceServer flush_srv_;
  ros::Subscriber estimate_sub_;
  std::unique_ptr<ReconfigureServer<unsup_mvs::KeyframeSelectorConfig>> reconfigure_;
};

boost::shared_ptr<nodelet::Nodelet> make_keyframe_selector_nodelet() {
  return boost::make_shared<KeyframeSelectorNodelet>();
}

}  // namespace umvs_ros

PLUGINLIB_EXPORT_CLASS(umvs_ros::KeyframeSelectorNodelet, nodelet::Nodelet)
