// Synthetic scenes with exact ground truth: a deterministic, multi-threaded ray caster of textured
// primitives (rectangles, boxes, spheres, capped cylinders). Textures are solid (a function of the
// world point), so every view sees the same surface colour; lighting may change between views.
//
// World frame: z up, metres. Cameras follow camera.h (x right, y down, z forward).
// Depth is the z-depth of the surface hit by the ray through the pixel centre (0 = nothing hit);
// colours are the average of supersample x supersample rays spread over the pixel.
//
// Scenes (sizes follow their use):
//   kDtuLike  objects on a table seen on an orbit at ~0.6 m (depths ~0.4-1 m, like DTU's 425-935 mm),
//             empty background (depth 0) like DTU's black backdrop;
//   kRoom     a furnished 6 x 5 x 2.6 m room seen from a robot path (depths ~0.5-8 m), closed;
//   kFacade   a street with buildings, trees and cars seen on a walk (depths ~2-40 m), open sky;
//   kCorridor a 20-30 m long office corridor (doors, pillars, radiators, benches, ceiling lights)
//             seen by a robot driving along it (depths ~0.3-30 m), closed.
// Photographic textures (SynthConfig::photo_textures, core/synth_textures.h) replace the procedural
// noise on a share of the textured surfaces; textureless surfaces stay textureless.
// LibTorch + Eigen only.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

enum class SynthSceneType { kDtuLike, kRoom, kFacade, kCorridor };
// kDefault = the scene's natural one. kOrbit: an object scan; kForward: a walk with the camera
// turned towards the scene; kRandom: eyes and targets uniform in boxes; kDrive: a ground robot
// driving forward and turning slowly, camera at a random height (0.3-1.5 m in metric scenes),
// small steps; kTurn: the robot turning in place, the camera a little in front of the axis.
enum class SynthTrajectory { kDefault, kOrbit, kForward, kRandom, kDrive, kTurn };

struct SynthConfig {
  SynthSceneType scene = SynthSceneType::kRoom;
  uint64_t seed = 1;             // scene layout, textures, lighting and random trajectories
  // Another pass through the same scene under the same lights (e.g. to judge an adaptation on
  // images it never saw): the camera path alone is drawn from it. Unset = the recipe's path.
  std::optional<uint64_t> path_seed;
  int num_views = 10;
  int width = 320, height = 256;
  // kDefault: kOrbit for kDtuLike, kForward for kRoom and kFacade, kDrive for kCorridor.
  SynthTrajectory trajectory = SynthTrajectory::kDefault;
  // Per-view global gain/bias and a Lambertian point light that moves between views. Off: one
  // fixed light and no gain/bias, so every view sees the same radiance (and no specular).
  bool lighting_change = true;
  bool specular = false;         // Blinn-Phong highlights (view dependent); only with lighting_change
  // Multiplies the contrast of every texture: 0 = uniform albedo per surface (textureless),
  // 1 = default multi-scale textures (some surfaces are weakly textured on purpose).
  double texture_strength = 1.0;
  // Photographs (uint8 [H,W,3], io/texture_bank.h loads them): each textured surface wears one
  // with probability photo_texture_fraction (random image, size, rotation, tint; drawn from the
  // seed), the others keep procedural textures. Empty = procedural only (as before).
  std::vector<torch::Tensor> photo_textures;
  double photo_texture_fraction = 0.75;
  int supersample = 2;           // anti-aliasing rays per pixel along each axis (1 = none)
  // Points sampled uniformly (by area) on all surfaces for the ground-truth cloud before keeping
  // those some view sees; 0 = no cloud (saves time in tests).
  int gt_cloud_samples = 300000;
};

struct SynthView {
  Camera camera;          // width/height set
  torch::Tensor image;    // uint8 [H,W,3] RGB
  torch::Tensor depth;    // float32 [H,W] z-depth, 0 where nothing is hit
};

struct SynthScene {
  std::vector<SynthView> views;
  // The depth range for cams/*.txt: the nearest and farthest surface any view sees, widened by 5%.
  double depth_min = 0, depth_max = 0;
  // Pair ranking by MVSNet's view-selection score (core/view_selection.h) over the surface points
  // the reference sees: per view (source id, score), best first, up to 10.
  std::vector<std::vector<std::pair<int, double>>> pairs;
  // Surface points seen by at least one view, uniform by area, coloured with the albedo (no light).
  PointCloud gt_cloud;
  double gt_cloud_spacing = 0;  // mean spacing of the area samples (scene units)
};

// Throws std::invalid_argument naming the bad field (sizes, view count, supersample, strength,
// photo textures).
SynthScene render_synthetic_scene(const SynthConfig& config);

// "dtu_like" | "room" | "facade" | "corridor" and "default" | "orbit" | "forward" | "random" |
// "drive" | "turn"; parse errors
// throw std::invalid_argument listing the accepted names.
SynthSceneType synth_scene_from_string(const std::string& name);
std::string to_string(SynthSceneType scene);
SynthTrajectory synth_trajectory_from_string(const std::string& name);
std::string to_string(SynthTrajectory trajectory);

}  // namespace umvs
