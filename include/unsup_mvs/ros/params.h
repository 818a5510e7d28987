// rosparam -> core Config structs, one helper per struct (voxblox's ros_params.h). Missing
// parameters keep the struct's documented defaults; the result is validated (throws
// std::invalid_argument naming the parameter).
#pragma once

#include <ros/node_handle.h>

#include <string>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/keyframes.h"

namespace umvs_ros {

// Largest image (width * height) a node accepts in a message by default (~max_image_pixels):
// 4096 x 4096, 48 MiB as rgb8. See docs/reliability.md, "Resource bounds (nodes)".
constexpr int kDefaultMaxImagePixels = 4096 * 4096;

// $ROS_HOME, else $HOME/.ros (else /tmp/.ros): where nodes keep their files by default.
std::string ros_home();

umvs::KeyframeConfig keyframe_config_from_ros(const ros::NodeHandle& nh);
// The keyframe policy plus ~rectified, ~depth_min, ~depth_max, defaults from KeyframeStreamConfig:
// read by the keyframe_selector from its namespace and by the trainer from its ~keyframes/ (the
// launch files load the same YAML into both).
umvs::KeyframeStreamConfig keyframe_stream_config_from_ros(const ros::NodeHandle& nh);
umvs::FusionConfig fusion_config_from_ros(const ros::NodeHandle& nh);

}  // namespace umvs_ros
