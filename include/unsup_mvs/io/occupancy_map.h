// An occupancy map for planners, built from depth maps (OctoMap, Hornung et al. 2013): each
// confident depth pixel is a ray from its camera, free along the way and occupied at its end
// (octomap's probabilistic update, clamped). Saved as a binary .bt file that octomap's tools
// (octovis, octomap_server) read, and projected to a 2-D grid over a height band
// (nav_msgs/OccupancyGrid's convention: 0 free, 100 occupied, -1 unknown). The update is what
// makes the map forget what moved: rays through a cell that an object has left lower its
// log-odds each time, and after enough of them (about nine depth maps at octomap's clamping and the
// default probabilities) it is free again, while a single noisy ray cannot free a wall. Needs liboctomap
// (UMVS_HAVE_OCTOMAP); without it the constructor throws std::runtime_error saying so.
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
  void validate() const;        // throws std::invalid_argument naming the field
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

  // depth, confidence: [H,W] of `camera` (confidence undefined = all confident). Returns the
  // number of rays cast.
  int64_t integrate(const torch::Tensor& depth, const torch::Tensor& confidence, const Camera& camera);

  // Occupied if any leaf in the column between z_min and z_max (world z) is occupied, free if
  // none is and one is free, unknown otherwise.
  OccupancyGrid2D project(double z_min, double z_max) const;

  // -1 unknown, 0 free, 1 occupied at a world point.
  int state_at(const Eigen::Vector3d& point) const;
  size_t occupied_leaves() const;
  size_t free_leaves() const;

  // Writes the binary .bt atomically (an existing file is kept when writing fails).
  void save(const std::string& path) const;
  void clear();
  // Live tuning: probabilities, range, confidence and stride apply to the depth maps integrated
  // from now on; a new resolution starts an empty map (the leaves cannot be resized). Returns
  // whether the map was cleared. Throws std::invalid_argument naming the field, keeping the old
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
