// The inference nodelet's depth map as a depth camera for ROS consumers (REP 118), under
// OpenNI-style names in one optical frame (the reference camera's), so that depth_image_proc's
// nodelets run with no remap beyond their namespace:
//   depth/image + depth/camera_info                          32FC1 metres, NaN unknown (point_cloud_xyz)
//   depth/image_raw                                          16UC1 millimetres, 0 unknown (convert_metric, rtabmap)
//   depth_registered/image_rect + depth_registered/camera_info  the same depth: it is made in the colour camera
//   rgb/image_rect_color + rgb/camera_info                   the reference's colour at the depth map's size
// point_cloud_xyzrgb takes the last two pairs as they are. depth/rgb (the colour without its own
// camera_info) stays for one release. Each topic is converted only while it has a subscriber.
#pragma once

#include <image_transport/image_transport.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <torch/types.h>

namespace umvs_ros {

class DepthCameraOutputs {
 public:
  // Advertises every topic on `it`; the callbacks run when a subscriber comes or goes.
  DepthCameraOutputs(image_transport::ImageTransport& it, const image_transport::SubscriberStatusCallback& image_status,
                     const ros::SubscriberStatusCallback& info_status);

  bool has_subscribers() const;

  // depth, confidence: float [H,W] of `info`; pixels below min_confidence are unknown. rgb: the
  // reference's rgb8 image at the same size (empty: no colour topics published).
  void publish(const torch::Tensor& depth, const torch::Tensor& confidence, double min_confidence,
               const sensor_msgs::Image& rgb, const sensor_msgs::CameraInfo& info);

 private:
  image_transport::CameraPublisher depth_, registered_, rgb_;
  image_transport::Publisher depth_raw_, legacy_rgb_;
};

}  // namespace umvs_ros
