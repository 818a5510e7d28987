// rosparam -> core Config structs, one helper per struct (voxblox's ros_params.h). Missing
// parameters keep the struct's documented defaults; the result is validated (throws
// std::invalid_argument naming the parameter).
#pragma once

#include <ros/node_handle.h>

#include <string>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/core/recommended_estimator.h"
#include "unsup_mvs/io/cloud_filter.h"
#include "unsup_mvs/io/occupancy_map.h"
#include "unsup_mvs/jobs/fine_tune_job.h"

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

// The inference nodelet's estimator: the product's recommended settings (as `umvs infer`).
inline umvs::DepthEstimatorConfig inference_estimator_defaults() { return umvs::recommended_estimator_config(); }

// The inference nodelet's parameters (docs/ros.md), validated: validate() throws
// std::invalid_argument naming the parameter.
struct InferenceNodeConfig {
  std::string device = "cpu";
  int threads = 0;                            // 0 = all cores
  umvs::DepthEstimatorConfig estimator = inference_estimator_defaults();
  bool rectified = umvs::KeyframeStreamConfig{}.rectified;  // as the keyframe_selector reads CameraInfo
  std::string checkpoint;
  int max_image_pixels = kDefaultMaxImagePixels;
  int max_views = 16;
  int max_planes = 256;
  int max_checkpoint_mb = 256;
  double reload_timeout = 60.0;  // s
  int queue_size = 4;  // keyframe sets waiting while the network is busy (the oldest is dropped beyond)
  // > 0: correct the keyframes' orientations online (umvs::KeyframePoseRefiner, this search limit
  // in degrees); 0 = off. The refiner remembers pose_refinement_keyframes keyframes.
  double pose_refinement_deg = 0.0;
  int pose_refinement_keyframes = 100;
  // depth/image (REP 118): pixels below this confidence are NaN, as are those without an estimate.
  double depth_camera_min_confidence = 0.5;
  void validate() const;
};
InferenceNodeConfig inference_node_config_from_ros(const ros::NodeHandle& nh);

// The fusion nodelet's parameters besides the FusionConfig thresholds.
struct FusionNodeConfig {
  umvs::FusionConfig fusion;
  std::string world_frame = "world";
  int window = 8;                 // depth maps kept for confirming points
  int max_points = 2000000;
  double publish_rate = 1.0;      // Hz
  std::string device = "cpu";
  std::string save_dir;           // "" = $ROS_HOME/unsup_mvs_clouds
  std::string default_save_path = "unsup_mvs_cloud.ply";
  int max_image_pixels = 2048 * 2048;
  umvs::CloudFilterConfig filters;  // ~filter/: applied to the published and saved map (all off by default)
  // ~occupancy/: the OctoMap every accepted depth map is ray-cast into (io/occupancy_map.h) and the
  // height band (world z, metres) projected to the published nav_msgs/OccupancyGrid.
  bool occupancy = true;
  // Every pixel casts a ray: a stride of 2 leaves rays from small maps wider apart than a leaf
  // (cells never crossed are never cleared) and saves little (HoloLens, 150 maps: 7.7 against 11 ms
  // per map; octomap merges the rays that end in one leaf).
  umvs::OccupancyMapConfig occupancy_map;
  double grid_min_z = 0.1, grid_max_z = 1.5;
  // The whole grid is republished (latched) at most this often, in seconds; the changed window goes
  // out on occupancy_grid_updates at every publish.
  double full_grid_period = 10.0;
  void validate() const;
};
FusionNodeConfig fusion_node_config_from_ros(const ros::NodeHandle& nh);

// The trainer node's job settings: ~umvs_path (default: umvs next to this executable),
// ~output_dir ("" = $ROS_HOME/unsup_mvs_models, ~/.ros without ROS_HOME), ~image_topic, ~camera_info_topic, ~world_frame,
// ~steps (FineTuneConfig::default_steps), ~train_args and ~keyframes/ (keyframe_stream_config_from_ros).
// Throws std::invalid_argument naming the parameter.
umvs::FineTuneConfig fine_tune_config_from_ros(const ros::NodeHandle& nh);

// All of the trainer node's parameters (docs/ros.md).
struct TrainerNodeConfig {
  umvs::FineTuneConfig job;
  std::string served_checkpoint;  // the model inference serves ("" = unknown: requests are refused)
  std::string reload_service = "/unsup_mvs/inference/reload_model";
  double poll_period = 0.5;       // s between progress updates
  void validate() const;          // throws std::invalid_argument naming the parameter
};
TrainerNodeConfig trainer_node_config_from_ros(const ros::NodeHandle& nh);

}  // namespace umvs_ros
