#include "unsup_mvs/ros/params.h"

#include <nodelet/loader.h>
#include <ros/ros.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fusion_settings.h"
#include "unsup_mvs/io/cloud_file.h"
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
  nh.param("lookahead", c.lookahead, c.lookahead);
  nh.param("max_wait_s", c.max_wait_s, c.max_wait_s);
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
  for (const auto& setting : umvs::fusion_settings()) {
    if (setting.on_node) setting.visit(c, [&](auto& field) { nh.param(setting.name, field, field); });
  }
  std::string rule = umvs::to_string(c.source_rule);
  nh.param("source_rule", rule, rule);
  c.source_rule = umvs::fusion_source_rule_from_string(rule);
  c.validate();
  return c;
}

void InferenceNodeConfig::validate() const {
  umvs::parse_device(device);
  const double completion = estimator.completion.min_confidence;
  if (!(completion >= 0.0 && completion < 1.0)) {
    throw std::invalid_argument("complete_below_confidence must be a confidence in [0,1) (0 = off), got " +
                                std::to_string(completion));
  }
  if (!(depth_camera_min_confidence >= 0.0 && depth_camera_min_confidence <= 1.0)) {
    throw std::invalid_argument("depth_camera_min_confidence must be a confidence in [0,1], got " +
                                std::to_string(depth_camera_min_confidence));
  }
  estimator.validate();
  // The network input is cropped to multiples of 32: a smaller bound leaves no image.
  for (const auto& [name, size] : {std::pair<const char*, int>{"max_width", estimator.max_width},
                                   std::pair<const char*, int>{"max_height", estimator.max_height}}) {
    if (size != 0 && size < 32) {
      throw std::invalid_argument(std::string(name) + " must be 0 (no limit) or at least 32, got " + std::to_string(size));
    }
  }
  if (max_image_pixels < 1 || max_views < 2 || max_planes < 8 || max_checkpoint_mb < 1 || !(reload_timeout > 0)) {
    throw std::invalid_argument("need max_image_pixels >= 1, max_views >= 2, max_planes >= 8, max_checkpoint_mb >= 1 "
                                "and reload_timeout > 0");
  }
  if (queue_size < 1) throw std::invalid_argument("queue_size must be >= 1, got " + std::to_string(queue_size));
  if (!std::isfinite(pose_refinement_deg) || pose_refinement_deg < 0) {
    throw std::invalid_argument("pose_refinement_deg must be an angle >= 0 (0 = off), got " + std::to_string(pose_refinement_deg));
  }
  if (pose_refinement_keyframes < max_views) {  // a set's keyframes must all be remembered
    throw std::invalid_argument("pose_refinement_keyframes must be at least max_views (" + std::to_string(max_views) +
                                "), got " + std::to_string(pose_refinement_keyframes));
  }
  if (estimator.num_depth > max_planes) {
    throw std::invalid_argument("num_depth " + std::to_string(estimator.num_depth) + " is more than max_planes " +
                                std::to_string(max_planes));
  }
  if (estimator.fine.planes > max_planes) {
    throw std::invalid_argument("fine_planes " + std::to_string(estimator.fine.planes) + " is more than max_planes " +
                                std::to_string(max_planes));
  }
}

InferenceNodeConfig inference_node_config_from_ros(const ros::NodeHandle& nh) {
  InferenceNodeConfig c;
  nh.param("device", c.device, c.device);
  nh.param("threads", c.threads, c.threads);
  nh.param("num_depth", c.estimator.num_depth, c.estimator.num_depth);
  nh.param("max_width", c.estimator.max_width, c.estimator.max_width);
  nh.param("max_height", c.estimator.max_height, c.estimator.max_height);
  std::string source_combination = umvs::to_string(c.estimator.source_combination);
  nh.param("source_combination", source_combination, source_combination);
  c.estimator.source_combination = umvs::source_combination_from_string(source_combination);
  nh.param("source_rotation_search_deg", c.estimator.source_rotation_search_deg, c.estimator.source_rotation_search_deg);
  nh.param("complete_below_confidence", c.estimator.completion.min_confidence, c.estimator.completion.min_confidence);
  nh.param("min_parallax_px", c.estimator.min_parallax_px, c.estimator.min_parallax_px);
  nh.param("fine_planes", c.estimator.fine.planes, c.estimator.fine.planes);
  nh.param("fine_span", c.estimator.fine.span, c.estimator.fine.span);
  nh.param("fine_resolution", c.estimator.fine.resolution_divisor, c.estimator.fine.resolution_divisor);
  nh.param("first_pass_downscale", c.estimator.fine.first_pass_downscale, c.estimator.fine.first_pass_downscale);
  nh.param("rectified", c.rectified, c.rectified);
  nh.param("checkpoint", c.checkpoint, c.checkpoint);
  nh.param("max_image_pixels", c.max_image_pixels, c.max_image_pixels);
  nh.param("max_views", c.max_views, c.max_views);
  nh.param("max_planes", c.max_planes, c.max_planes);
  nh.param("max_checkpoint_mb", c.max_checkpoint_mb, c.max_checkpoint_mb);
  nh.param("reload_timeout", c.reload_timeout, c.reload_timeout);
  nh.param("queue_size", c.queue_size, c.queue_size);
  nh.param("pose_refinement_deg", c.pose_refinement_deg, c.pose_refinement_deg);
  nh.param("pose_refinement_keyframes", c.pose_refinement_keyframes, c.pose_refinement_keyframes);
  nh.param("depth_camera_min_confidence", c.depth_camera_min_confidence, c.depth_camera_min_confidence);
  c.validate();
  return c;
}

void FusionNodeConfig::validate() const {
  fusion.validate();
  occupancy_map.validate();
  if (!(grid_max_z > grid_min_z)) throw std::invalid_argument("occupancy/grid_max_z must be above occupancy/grid_min_z");
  if (!(full_grid_period > 0) || !std::isfinite(full_grid_period)) {
    throw std::invalid_argument("occupancy/full_grid_period must be > 0 seconds");
  }
  umvs::parse_device(device);
  if (max_image_pixels < 1) throw std::invalid_argument("max_image_pixels must be >= 1");
  if (window < 1) throw std::invalid_argument("window must be >= 1");
  if (max_points < 1) throw std::invalid_argument("max_points must be >= 1");
  if (!(publish_rate > 0)) throw std::invalid_argument("publish_rate must be > 0");
  try {
    umvs::cloud_file_format(default_save_path);  // save_cloud with an empty path must be able to write it
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("default_save_path: ") + e.what());
  }
  try {
    filters.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("~filter/: ") + e.what());
  }
}

FusionNodeConfig fusion_node_config_from_ros(const ros::NodeHandle& nh) {
  FusionNodeConfig c;
  c.fusion = fusion_config_from_ros(nh);
  nh.param("world_frame", c.world_frame, c.world_frame);
  nh.param("window", c.window, c.window);
  nh.param("max_points", c.max_points, c.max_points);
  nh.param("publish_rate", c.publish_rate, c.publish_rate);
  nh.param("device", c.device, c.device);
  nh.param("save_dir", c.save_dir, c.save_dir);
  if (c.save_dir.empty()) c.save_dir = ros_home() + "/unsup_mvs_clouds";
  nh.param("default_save_path", c.default_save_path, c.default_save_path);
  nh.param("max_image_pixels", c.max_image_pixels, c.max_image_pixels);
  const ros::NodeHandle filter(nh, "filter");
  filter.param("sor_mean_k", c.filters.sor_mean_k, c.filters.sor_mean_k);
  filter.param("sor_std_mul", c.filters.sor_std_mul, c.filters.sor_std_mul);
  filter.param("radius", c.filters.radius, c.filters.radius);
  filter.param("radius_min_neighbors", c.filters.radius_min_neighbors, c.filters.radius_min_neighbors);
  filter.param("voxel_leaf", c.filters.voxel_leaf, c.filters.voxel_leaf);
  const ros::NodeHandle occupancy(nh, "occupancy");
  occupancy.param("enabled", c.occupancy, c.occupancy);
  occupancy.param("resolution", c.occupancy_map.resolution, c.occupancy_map.resolution);
  occupancy.param("max_range", c.occupancy_map.max_range, c.occupancy_map.max_range);
  occupancy.param("prob_hit", c.occupancy_map.prob_hit, c.occupancy_map.prob_hit);
  occupancy.param("prob_miss", c.occupancy_map.prob_miss, c.occupancy_map.prob_miss);
  occupancy.param("min_confidence", c.occupancy_map.min_confidence, c.occupancy_map.min_confidence);
  occupancy.param("pixel_stride", c.occupancy_map.pixel_stride, c.occupancy_map.pixel_stride);
  int max_nodes = static_cast<int>(c.occupancy_map.max_nodes);  // XmlRpc integers are 32-bit
  occupancy.param("max_nodes", max_nodes, max_nodes);
  c.occupancy_map.max_nodes = max_nodes;
  std::vector<double> extent;
  if (occupancy.hasParam("extent")) {
    if (!occupancy.getParam("extent", extent)) {
      throw std::invalid_argument("occupancy/extent must be a list [min_x, min_y, min_z, max_x, max_y, max_z] of "
                                  "numbers (metres, world frame)");
    }
    if (extent.size() != 6) {
      throw std::invalid_argument("occupancy/extent must be [min_x, min_y, min_z, max_x, max_y, max_z] (metres, world "
                                  "frame), got " + std::to_string(extent.size()) + " numbers");
    }
    auto& m = c.occupancy_map;
    std::tie(m.min_x, m.min_y, m.min_z, m.max_x, m.max_y, m.max_z) =
        std::tie(extent[0], extent[1], extent[2], extent[3], extent[4], extent[5]);
  }
  occupancy.param("full_grid_period", c.full_grid_period, c.full_grid_period);
  occupancy.param("grid_min_z", c.grid_min_z, c.grid_min_z);
  occupancy.param("grid_max_z", c.grid_max_z, c.grid_max_z);
  c.validate();
  return c;
}

umvs::FineTuneConfig fine_tune_config_from_ros(const ros::NodeHandle& nh) {
  umvs::FineTuneConfig c;
  // The tool is built next to this node's executable (devel/lib/unsup_mvs/).
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  c.umvs_path = ec ? std::string() : (self.parent_path() / "umvs").string();
  nh.param("umvs_path", c.umvs_path, c.umvs_path);
  nh.param("output_dir", c.output_dir, c.output_dir);
  if (c.output_dir.empty()) c.output_dir = ros_home() + "/unsup_mvs_models";  // as fusion's clouds
  nh.param("image_topic", c.image_topic, c.image_topic);
  nh.param("camera_info_topic", c.camera_info_topic, c.camera_info_topic);
  nh.param("world_frame", c.world_frame, c.world_frame);
  nh.param("device", c.device, c.device);
  nh.param("steps", c.default_steps, c.default_steps);
  nh.param("train_args", c.train_args, c.train_args);
  nh.param("local_ranks", c.local_ranks, c.local_ranks);
  nh.param("fine_tuned_share", c.fine_tuned_share, c.fine_tuned_share);
  // The bags are read as the keyframe_selector reads the live stream: the launch files load its
  // YAML (and ~rectified) into ~keyframes/ too.
  try {
    c.keyframes = keyframe_stream_config_from_ros(ros::NodeHandle(nh, "keyframes"));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("invalid ~keyframes/ parameters: ") + e.what());
  }
  try {
    c.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("invalid parameters: ") + e.what());
  }
  return c;
}

void TrainerNodeConfig::validate() const {
  job.validate();
  if (reload_service.empty()) throw std::invalid_argument("reload_service must not be empty");
  if (!(poll_period > 0)) throw std::invalid_argument("poll_period must be > 0, got " + std::to_string(poll_period));
}

TrainerNodeConfig trainer_node_config_from_ros(const ros::NodeHandle& nh) {
  TrainerNodeConfig c;
  c.job = fine_tune_config_from_ros(nh);
  nh.param("served_checkpoint", c.served_checkpoint, c.served_checkpoint);
  nh.param("reload_service", c.reload_service, c.reload_service);
  nh.param("poll_period", c.poll_period, c.poll_period);
  try {
    c.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("invalid parameters: ") + e.what());
  }
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
