#include "unsup_mvs/ros/params.h"

#include <nodelet/loader.h>
#include <ros/ros.h>

#include <cstdlib>

#include "unsup_mvs/ros/nodelets.h"

namespace umvs_ros {

std::string ros_home() {
  if (const char* env = std::getenv("ROS_HOME"); env && *env) return env;
  const char* home = std::getenv("HOME");
  return std::string(home && *home ? home : "/tmp") + "/.ros";
}

umvs::KeyframeConfig keyframe_config_from_ros(const ros::NodeHandle& nh) {
  umvs::KeyframeConfig c;
  nh.param("min_translation", c.min_translation, c.min_translation);
  nh.param("min_rotation_deg", c.min_rotation_deg, c.min_rotation_deg);
  nh.param("min_pose_distance", c.min_pose_distance, c.min_pose_distance);
  nh.param("buffer_size", c.buffer_size, c.buffer_size);
  nh.param("num_sources", c.num_sources, c.num_sources);
  nh.param("min_view_score", c.min_score, c.min_score);
  nh.param("view_score_grid", c.score_grid, c.score_grid);
  c.validate();
  return c;
}

umvs::KeyframeStreamConfig keyframe_stream_config_from_ros(const ros::NodeHandle& nh) {
  umvs::KeyframeStreamConfig c;
  c.keyframes = keyframe_config_from_ros(nh);
  nh.param("rectified", c.rectified, c.rectified);
  nh.param("depth_min", c.depth_min, c.depth_min);
  nh.param("depth_max", c.depth_max, c.depth_max);
  c.validate();
  return c;
}

umvs::FusionConfig fusion_config_from_ros(const ros::NodeHandle& nh) {
  umvs::FusionConfig c;
  nh.param("min_confidence", c.min_confidence, c.min_confidence);
  nh.param("max_reprojection_px", c.max_reprojection_px, c.max_reprojection_px);
  nh.param("max_relative_depth", c.max_relative_depth, c.max_relative_depth);
  nh.param("min_agreeing_views", c.min_agreeing_views, c.min_agreeing_views);
  nh.param("voxel_size", c.voxel_size, c.voxel_size);
  std::string rule = umvs::to_string(c.source_rule);
  nh.param("source_rule", rule, rule);
  c.source_rule = umvs::fusion_source_rule_from_string(rule);
  c.validate();
  return c;
}

int run_standalone(int argc, char** argv, const std::string& default_name,
                   boost::shared_ptr<nodelet::Nodelet> (*factory)()) {
  ros::init(argc, argv, default_name);
  nodelet::Loader loader([factory](const std::string&) { return factory(); });
  const nodelet::M_string remappings(ros::names::getRemappings());
  const nodelet::V_string nodelet_argv;
  if (!loader.load(ros::this_node::getName(), "unsup_mvs/standalone", remappings, nodelet_argv)) {
    ROS_FATAL("%s: could not start the nodelet", ros::this_node::getName().c_str());
    return 1;
  }
  ros::spin();
  return 0;
}

}  // namespace umvs_ros
