// An occupancy map for planners, built from depth maps (OctoMap, Hornung et al. 2013): each
// confident depth pixel is a ray from its camera, free along the way and occupied at its end
// (octomap's probabilistic update, clamped). Saved as a binary .bt file that octomap's tools
// (octovis, octomap_server) read, and projected to a 2-D grid over a height band
// (nav_msgs/OccupancyGrid's convention: 0 free, 100 occupied, -1 unknown). The update is what
// makes the map forget what moved: rays through a cell that an object has left lower its
// log-odds each time, and after enough of them (about nine depth maps at octomap's clamping and the
// default probabilities) it is free again, while a single noisy ray cannot free a wall. Needs liboctomap
// (UMVS_HAVE_OCTOMAP); without it the constructor throws std::runtime_error saying so.
//
// The map is bounded, so that it can run for hours: it covers a configured box of the world frame
// (by default a building floor, 50 x 50 m around the world origin and -2..4 m high), nothing outside
// it is ever allocated (a ray leaving the box clears space only up to its wall), a depth map whose
// camera is outside the box is skipped whole, and the octree stops growing at a node cap (rays
// then only update the cells it holds at full resolution). The 2-D grid is the box's x-y footprint: its size and
// origin never change, not even when the map is cleared.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "unsup_mvs/core/camera.h"

namespace umvs {

struct OccupancyMapConfig {
  double resolution = 0.05;     // leaf edge, metres
  double max_range = 5.0;       // rays are cut here (metres); farther surfaces only clear space
  double prob_hit = 0.7;        // occupancy probability of a ray's end
  double prob_miss = 0.4;       // ... of a cell a ray passes through
  double min_confidence = 0.5;  // depth pixels below this confidence cast no ray
  int pixel_stride = 1;         // every N-th depth pixel each way
  // The map's extent: a box in the world frame (metres).
  double min_x = -25.0, min_y = -25.0, min_z = -2.0;
  double max_x = 25.0, max_y = 25.0, max_z = 4.0;
  // Octree nodes at most (leaves and the inner nodes above them, about 40 bytes each with
  // octomap's allocation: 2,000,000 is about 80 MB).
  int64_t max_nodes = 2'000'000;
  void validate() const;        // throws std::invalid_argument naming the field
  bool contains(const Eigen::Vector3d& point) const;
};

// What one depth map did to the map.
struct OccupancyIntegration {
  int64_t rays = 0;           // confident pixels cast as rays (0 when the camera was outside)
  int64_t cut = 0;            // of those, rays cut at the range limit or the extent's wall: they only clear
  bool camera_outside = false;  // the camera was outside the extent: nothing was inserted
  bool at_node_cap = false;     // the octree reached max_nodes: only cells it held at full resolution were updated
};

// A 2-D projection: row-major, cell (0,0) at (origin_x, origin_y), +x right, +y up (REP 103 in
// the map frame).
struct OccupancyGrid2D {
  double resolution = 0.0;
  double origin_x = 0.0, origin_y = 0.0;
  int width = 0, height = 0;
  std::vector<int8_t> cells;  // 0 free, 100 occupied, -1 unknown
};

class OccupancyMap {
 public:
  explicit OccupancyMap(const OccupancyMapConfig& config);
  ~OccupancyMap();
  OccupancyMap(OccupancyMap&&) noexcept;
  OccupancyMap& operator=(OccupancyMap&&) noexcept;

  // depth, confidence: [H,W] of `camera` (confidence undefined = all confident).
  OccupancyIntegration integrate(const torch::Tensor& depth, const torch::Tensor& confidence, const Camera& camera);

  // The extent's x-y footprint at the map's resolution: occupied if any leaf in the column between
  // z_min and z_max (world z) is occupied, free if none is and one is free, unknown otherwise.
  OccupancyGrid2D project(double z_min, double z_max) const;
  size_t nodes() const;  // octree nodes (the quantity max_nodes caps)

  // -1 unknown, 0 free, 1 occupied at a world point.
  int state_at(const Eigen::Vector3d& point) const;
  size_t occupied_leaves() const;
  size_t free_leaves() const;

  // Writes the binary .bt atomically (an existing file is kept when writing fails).
  void save(const std::string& path) const;
  void clear();
  // Live tuning: probabilities, range, confidence, stride and the node cap apply to the depth maps
  // integrated from now on; a new resolution or extent starts an empty map (the leaves cannot be
  // resized, and a smaller box would keep cells outside it). Returns whether the map was cleared. Throws std::invalid_argument naming the field, keeping the old
  // settings.
  bool set_config(const OccupancyMapConfig& config);
  const OccupancyMapConfig& config() const { return config_; }

 private:
  struct Tree;
  OccupancyMapConfig config_;
  std::unique_ptr<Tree> tree_;
};

// Whether this build has OctoMap.
bool occupancy_maps_available();

}  // namespace umvs
