#include "unsup_mvs/ros/depth_camera_outputs.h"

#include "unsup_mvs/io/ros/ros_conversions.h"

namespace umvs_ros {

DepthCameraOutputs::DepthCameraOutputs(image_transport::ImageTransport& it,
                                       const image_transport::SubscriberStatusCallback& image_status,
                                       const ros::SubscriberStatusCallback& info_status) {
  depth_ = it.advertiseCamera("depth/image", 2, image_status, image_status, info_status, info_status);
  depth_raw_ = it.advertise("depth/image_raw", 2, image_status, image_status);
  registered_ = it.advertiseCamera("depth_registered/image_rect", 2, image_status, image_status, info_status, info_status);
  rgb_ = it.advertiseCamera("rgb/image_rect_color", 2, image_status, image_status, info_status, info_status);
  legacy_rgb_ = it.advertise("depth/rgb", 2, image_status, image_status);
}

bool DepthCameraOutputs::has_subscribers() const {
  return depth_.getNumSubscribers() > 0 || depth_raw_.getNumSubscribers() > 0 || registered_.getNumSubscribers() > 0 ||
         rgb_.getNumSubscribers() > 0 || legacy_rgb_.getNumSubscribers() > 0;
}

void DepthCameraOutputs::publish(const torch::Tensor& depth, const torch::Tensor& confidence, double min_confidence,
                                 const sensor_msgs::Image& rgb, const sensor_msgs::CameraInfo& info) {
  const bool metres_wanted = depth_.getNumSubscribers() > 0 || registered_.getNumSubscribers() > 0 ||
                             depth_raw_.getNumSubscribers() > 0;
  if (metres_wanted) {
    const sensor_msgs::Image metres = umvs::depth_camera_image_msg(depth, confidence, min_confidence, info.header);
    if (depth_.getNumSubscribers() > 0) depth_.publish(metres, info);
    if (registered_.getNumSubscribers() > 0) registered_.publish(metres, info);
    if (depth_raw_.getNumSubscribers() > 0) depth_raw_.publish(umvs::depth_camera_image_16uc1_msg(metres));
  }
  if (rgb.data.empty()) return;
  if (rgb_.getNumSubscribers() > 0) rgb_.publish(rgb, info);
  if (legacy_rgb_.getNumSubscribers() > 0) legacy_rgb_.publish(rgb);
}

}  // namespace umvs_ros
