// rosparam -> core Config structs, one helper per struct (voxblox's ros_params.h). Missing
// parameters keep the struct's documented defaults; the result is validated (throws
// std::invalid_argument naming the parameter).
#pragma once

#include <ros/node_handle.h>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/keyframes.h"

namespace umvs_ros {

umvs::KeyframeConfig keyframe_config_from_ros(const ros::NodeHandle& nh);
umvs::FusionConfig fusion_config_from_ros(const ros::NodeHandle& nh);

}  // namespace umvs_ros
