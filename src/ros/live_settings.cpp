// The live-tunable subset of each node's settings (cfg/*.cfg), both ways: one mapping per node,
// used by the nodelets' reconfigure servers and by the test that checks the cfg defaults against
// the config structs'.
#include "unsup_mvs/ros/live_settings.h"

#include <stdexcept>
#include <string>

#include "unsup_mvs/core/fusion_settings.h"

namespace umvs_ros {
namespace {

// A setting's value in a dynamic_reconfigure message, by name (the cfg holds every node setting
// of the table: a test compares them).
void set_live(dynamic_reconfigure::Config& live, const std::string& name, double value, bool integer) {
  if (integer) {
    for (auto& p : live.ints) {
      if (p.name == name) return void(p.value = static_cast<int>(value));
    }
  } else {
    for (auto& p : live.doubles) {
      if (p.name == name) return void(p.value = value);
    }
  }
  throw std::logic_error("the setting " + name + " is not in the node's dynamic_reconfigure cfg");
}

double live_value(const dynamic_reconfigure::Config& live, const std::string& name) {
  for (const auto& p : live.ints) {
    if (p.name == name) return p.value;
  }
  for (const auto& p : live.doubles) {
    if (p.name == name) return p.value;
  }
  throw std::logic_error("the setting " + name + " is not in the node's dynamic_reconfigure cfg");
}

}  // namespace

// The live-tunable settings (cfg/Fusion.cfg), both ways: FusionConfig's by its settings table.
unsup_mvs::FusionConfig to_reconfigure(const FusionNodeConfig& node) {
  const umvs::FusionConfig& c = node.fusion;
  const umvs::OccupancyMapConfig& o = node.occupancy_map;
  unsup_mvs::FusionConfig r = unsup_mvs::FusionConfig::__getDefault__();
  dynamic_reconfigure::Config live;
  r.__toMessage__(live);
  for (const auto& setting : umvs::fusion_settings()) {
    if (setting.on_node) set_live(live, setting.name, setting.value(c), setting.is_integer());
  }
  r.__fromMessage__(live);
  r.occupancy_resolution = o.resolution;
  r.occupancy_max_range = o.max_range;
  r.occupancy_prob_hit = o.prob_hit;
  r.occupancy_prob_miss = o.prob_miss;
  r.occupancy_min_confidence = o.min_confidence;
  r.occupancy_pixel_stride = o.pixel_stride;
  r.occupancy_grid_min_z = node.grid_min_z;
  r.occupancy_grid_max_z = node.grid_max_z;
  return r;
}

FusionNodeConfig with_reconfigure(FusionNodeConfig node, const unsup_mvs::FusionConfig& r) {
  umvs::FusionConfig& c = node.fusion;
  umvs::OccupancyMapConfig& o = node.occupancy_map;
  dynamic_reconfigure::Config live;
  r.__toMessage__(live);
  for (const auto& setting : umvs::fusion_settings()) {
    if (setting.on_node) setting.visit(c, [&](auto& field) { field = live_value(live, setting.name); });
  }
  o.resolution = r.occupancy_resolution;
  o.max_range = r.occupancy_max_range;
  o.prob_hit = r.occupancy_prob_hit;
  o.prob_miss = r.occupancy_prob_miss;
  o.min_confidence = r.occupancy_min_confidence;
  o.pixel_stride = r.occupancy_pixel_stride;
  node.grid_min_z = r.occupancy_grid_min_z;
  node.grid_max_z = r.occupancy_grid_max_z;
  return node;
}

// The live-tunable network settings (cfg/Inference.cfg), both ways.
unsup_mvs::InferenceConfig to_reconfigure(const InferenceNodeConfig& c) {
  unsup_mvs::InferenceConfig r = unsup_mvs::InferenceConfig::__getDefault__();
  r.max_width = c.estimator.max_width;
  r.max_height = c.estimator.max_height;
  r.num_depth = c.estimator.num_depth;
  r.pose_refinement_deg = c.pose_refinement_deg;
  r.depth_camera_min_confidence = c.depth_camera_min_confidence;
  return r;
}

InferenceNodeConfig with_reconfigure(InferenceNodeConfig c, const unsup_mvs::InferenceConfig& r) {
  c.estimator.max_width = r.max_width;
  c.estimator.max_height = r.max_height;
  c.estimator.num_depth = r.num_depth;
  c.pose_refinement_deg = r.pose_refinement_deg;
  c.depth_camera_min_confidence = r.depth_camera_min_confidence;
  return c;
}

// The live-tunable part of the stream config (cfg/KeyframeSelector.cfg), both ways.
unsup_mvs::KeyframeSelectorConfig to_reconfigure(const umvs::KeyframeStreamConfig& c) {
  unsup_mvs::KeyframeSelectorConfig r = unsup_mvs::KeyframeSelectorConfig::__getDefault__();
  r.min_translation = c.keyframes.min_translation;
  r.min_rotation_deg = c.keyframes.min_rotation_deg;
  r.min_pose_distance = c.keyframes.min_pose_distance;
  r.buffer_size = c.keyframes.buffer_size;
  r.num_sources = c.keyframes.num_sources;
  r.lookahead = c.keyframes.lookahead;
  r.max_wait_s = c.keyframes.max_wait_s;
  r.min_view_score = c.keyframes.min_score;
  r.view_score_grid = c.keyframes.score_grid;
  r.depth_min = c.depth_min;
  r.depth_max = c.depth_max;
  return r;
}

umvs::KeyframeStreamConfig with_reconfigure(umvs::KeyframeStreamConfig c, const unsup_mvs::KeyframeSelectorConfig& r) {
  c.keyframes.min_translation = r.min_translation;
  c.keyframes.min_rotation_deg = r.min_rotation_deg;
  c.keyframes.min_pose_distance = r.min_pose_distance;
  c.keyframes.buffer_size = r.buffer_size;
  c.keyframes.num_sources = r.num_sources;
  c.keyframes.lookahead = r.lookahead;
  c.keyframes.max_wait_s = r.max_wait_s;
  c.keyframes.min_score = r.min_view_score;
  c.keyframes.score_grid = r.view_score_grid;
  c.depth_min = r.depth_min;
  c.depth_max = r.depth_max;
  return c;
}

}  // namespace umvs_ros
