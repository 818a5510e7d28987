#include "unsup_mvs/io/occupancy_map.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"

#ifdef UMVS_HAVE_OCTOMAP
#include <octomap/OcTree.h>
#endif

namespace umvs {

void OccupancyMapConfig::validate() const {
  auto fail = [](const std::string& m) { throw std::invalid_argument("occupancy map: " + m); };
  if (!(resolution > 0) || !std::isfinite(resolution)) fail("resolution must be > 0 metres");
  if (!(max_range > 0) || !std::isfinite(max_range)) fail("max_range must be > 0 metres");
  if (!(prob_hit > 0.5 && prob_hit < 1.0)) fail("prob_hit must be in (0.5, 1)");
  if (!(prob_miss > 0.0 && prob_miss < 0.5)) fail("prob_miss must be in (0, 0.5)");
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) fail("min_confidence must be in [0, 1]");
  if (pixel_stride < 1) fail("pixel_stride must be >= 1");
  for (const double v : {min_x, min_y, min_z, max_x, max_y, max_z}) {
    if (!std::isfinite(v)) fail("the extent (min_x .. max_z) must be finite metres");
  }
  if (!(max_x - min_x >= resolution && max_y - min_y >= resolution && max_z - min_z >= resolution)) {
    fail("the extent must be at least one leaf (resolution) across on every axis: max_x > min_x, max_y > min_y, "
         "max_z > min_z");
  }
  // octomap addresses 2^16 leaves per axis around the origin: keep the box inside that.
  const double reach = 32767.0 * resolution;
  if (std::max({-min_x, -min_y, -min_z, max_x, max_y, max_z}) >= reach) {
    fail("the extent reaches beyond what octomap can address at this resolution (+-" + std::to_string(reach) + " m)");
  }
  const double cells = std::ceil((max_x - min_x) / resolution) * std::ceil((max_y - min_y) / resolution);
  if (cells > 1e8) fail("the extent's 2-D grid would have " + std::to_string(cells) + " cells (at most 1e8)");
  if (max_nodes < 1) fail("max_nodes must be >= 1");
}

bool OccupancyMapConfig::contains(const Eigen::Vector3d& p) const {
  return p.x() >= min_x && p.x() <= max_x && p.y() >= min_y && p.y() <= max_y && p.z() >= min_z && p.z() <= max_z;
}

#ifdef UMVS_HAVE_OCTOMAP

struct OccupancyMap::Tree {
  explicit Tree(double resolution) : tree(resolution) {}
  octomap::OcTree tree;
};

bool occupancy_maps_available() { return true; }

OccupancyMap::OccupancyMap(const OccupancyMapConfig& config) : config_(config) {
  config_.validate();
  tree_ = std::make_unique<Tree>(config_.resolution);
  tree_->tree.setProbHit(config_.prob_hit);
  tree_->tree.setProbMiss(config_.prob_miss);
}

namespace {
// Where the segment from `origin` (inside the box) to `end` leaves the box of `c`: `end` itself
// when it is inside, else the point a thousandth of a leaf before the wall.
Eigen::Vector3d clip_to_extent(const OccupancyMapConfig& c, const Eigen::Vector3d& origin, const Eigen::Vector3d& end) {
  const Eigen::Vector3d d = end - origin;
  const Eigen::Vector3d lo(c.min_x, c.min_y, c.min_z), hi(c.max_x, c.max_y, c.max_z);
  double t = 1.0;
  for (int k = 0; k < 3; ++k) {
    if (d[k] > 0) t = std::min(t, (hi[k] - origin[k]) / d[k]);
    if (d[k] < 0) t = std::min(t, (lo[k] - origin[k]) / d[k]);
  }
  if (t >= 1.0) return end;
  const double length = d.norm();
  return origin + d * std::max(0.0, t - 1e-3 * c.resolution / std::max(length, 1e-12));
}

// Whether the tree holds the cell of `key` at full resolution: updating it then allocates nothing
// (a cell inside a pruned, coarser leaf would split it into eight).
bool holds_full_resolution_cell(const octomap::OcTree& tree, const octomap::OcTreeKey& key) {
  const octomap::OcTreeNode* node = tree.getRoot();
  const unsigned int depth = tree.getTreeDepth();
  for (unsigned int level = 0; node && level < depth; ++level) {
    const unsigned int child = octomap::computeChildIdx(key, static_cast<int>(depth - 1 - level));
    if (!tree.nodeChildExists(node, child)) return false;
    node = tree.getNodeChild(node, child);
  }
  return node != nullptr;
}
}  // namespace

OccupancyIntegration OccupancyMap::integrate(const torch::Tensor& depth, const torch::Tensor& confidence,
                                             const Camera& camera) {
  if (depth.dim() != 2 || depth.size(0) != camera.height || depth.size(1) != camera.width) {
    throw std::invalid_argument("occupancy map: the depth map must be [H,W] of its camera's size");
  }
  if (confidence.defined() && confidence.sizes() != depth.sizes()) {
    throw std::invalid_argument("occupancy map: confidence and depth differ in size");
  }
  OccupancyIntegration result;
  const Eigen::Vector3d origin = camera.center();
  if (!config_.contains(origin)) {
    result.camera_outside = true;
    return result;
  }
  const auto d = depth.to(torch::kFloat32).contiguous();
  const auto c = confidence.defined() ? confidence.to(torch::kFloat32).contiguous() : torch::ones_like(d);
  const auto da = d.accessor<float, 2>();
  const auto ca = c.accessor<float, 2>();
  auto& tree = tree_->tree;
  const octomap::point3d o(origin.x(), origin.y(), origin.z());
  // Hits: ray ends within range and inside the box. Every other ray only clears, up to the range
  // limit or the box's wall, whichever comes first.
  octomap::Pointcloud hits;
  std::vector<Eigen::Vector3d> clearing_ends;
  for (int64_t v = 0; v < d.size(0); v += config_.pixel_stride) {
    for (int64_t u = 0; u < d.size(1); u += config_.pixel_stride) {
      const float z = da[v][u];
      if (!(z > 0.0f) || !std::isfinite(z) || ca[v][u] < config_.min_confidence) continue;
      ++result.rays;
      const Eigen::Vector3d p = camera.backproject(static_cast<double>(u), static_cast<double>(v), z);
      const double length = (p - origin).norm();
      if (length <= config_.max_range && config_.contains(p)) {
        hits.push_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
        continue;
      }
      ++result.cut;
      const Eigen::Vector3d in_range = origin + (p - origin) * std::min(1.0, config_.max_range / length);
      clearing_ends.push_back(clip_to_extent(config_, origin, in_range));
    }
  }
  // octomap's own update (each cell once per depth map, occupied before free), with the clearing
  // rays' cells added as free.
  octomap::KeySet free_cells, occupied_cells;
  tree.computeDiscreteUpdate(hits, o, free_cells, occupied_cells, -1.0);
  octomap::KeyRay ray;
  for (const Eigen::Vector3d& end : clearing_ends) {
    if (!tree.computeRayKeys(o, octomap::point3d(end.x(), end.y(), end.z()), ray)) continue;
    for (const octomap::OcTreeKey& key : ray) {
      if (!occupied_cells.count(key)) free_cells.insert(key);
    }
  }
  const auto update = [&](const octomap::OcTreeKey& key, bool occupied) {
    if (tree.size() >= static_cast<size_t>(config_.max_nodes) && !holds_full_resolution_cell(tree, key)) {
      result.at_node_cap = true;  // the update would grow the tree past its cap
      return;
    }
    tree.updateNode(key, occupied, /*lazy_eval=*/false);
  };
  for (const octomap::OcTreeKey& key : free_cells) update(key, false);
  for (const octomap::OcTreeKey& key : occupied_cells) update(key, true);
  return result;
}

size_t OccupancyMap::nodes() const { return tree_->tree.size(); }

int OccupancyMap::state_at(const Eigen::Vector3d& p) const {
  const octomap::OcTreeNode* node = tree_->tree.search(p.x(), p.y(), p.z());
  if (!node) return -1;
  return tree_->tree.isNodeOccupied(node) ? 1 : 0;
}

size_t OccupancyMap::occupied_leaves() const {
  size_t n = 0;
  for (auto it = tree_->tree.begin_leafs(); it != tree_->tree.end_leafs(); ++it) n += tree_->tree.isNodeOccupied(*it);
  return n;
}

size_t OccupancyMap::free_leaves() const {
  size_t n = 0;
  for (auto it = tree_->tree.begin_leafs(); it != tree_->tree.end_leafs(); ++it) n += !tree_->tree.isNodeOccupied(*it);
  return n;
}

OccupancyGrid2D OccupancyMap::project(double z_min, double z_max) const {
  if (!(z_max > z_min)) throw std::invalid_argument("occupancy map: the height band needs z_max > z_min");
  OccupancyGrid2D grid;
  grid.resolution = config_.resolution;
  grid.origin_x = config_.min_x;
  grid.origin_y = config_.min_y;
  grid.width = static_cast<int>(std::ceil((config_.max_x - config_.min_x) / grid.resolution - 1e-9));
  grid.height = static_cast<int>(std::ceil((config_.max_y - config_.min_y) / grid.resolution - 1e-9));
  grid.cells.assign(static_cast<size_t>(grid.width) * grid.height, -1);
  // Leaves of any size: each covers the grid cells under its footprint.
  for (auto it = tree_->tree.begin_leafs(); it != tree_->tree.end_leafs(); ++it) {
    const double half = it.getSize() / 2;
    if (it.getZ() + half < z_min || it.getZ() - half > z_max) continue;
    const bool occupied = tree_->tree.isNodeOccupied(*it);
    const int i0 = std::max(0, static_cast<int>(std::floor((it.getX() - half - grid.origin_x) / grid.resolution + 1e-6)));
    const int j0 = std::max(0, static_cast<int>(std::floor((it.getY() - half - grid.origin_y) / grid.resolution + 1e-6)));
    const int i1 = std::min(grid.width, static_cast<int>(std::ceil((it.getX() + half - grid.origin_x) / grid.resolution - 1e-6)));
    const int j1 = std::min(grid.height, static_cast<int>(std::ceil((it.getY() + half - grid.origin_y) / grid.resolution - 1e-6)));
    for (int j = j0; j < j1; ++j) {
      for (int i = i0; i < i1; ++i) {
        int8_t& cell = grid.cells[static_cast<size_t>(j) * grid.width + i];
        if (occupied) cell = 100;
        else if (cell == -1) cell = 0;
      }
    }
  }
  return grid;
}

void OccupancyMap::save(const std::string& path) const {
  write_file_atomically(path, [&](std::ostream& out) {
    if (!tree_->tree.writeBinaryConst(out)) throw std::runtime_error("octomap could not write " + path);
  });
}

void OccupancyMap::clear() { tree_->tree.clear(); }

bool OccupancyMap::set_config(const OccupancyMapConfig& config) {
  config.validate();
  const bool new_map = config.resolution != config_.resolution || config.min_x != config_.min_x ||
                       config.min_y != config_.min_y || config.min_z != config_.min_z || config.max_x != config_.max_x ||
                       config.max_y != config_.max_y || config.max_z != config_.max_z;
  config_ = config;
  if (new_map) tree_ = std::make_unique<Tree>(config_.resolution);
  tree_->tree.setProbHit(config_.prob_hit);
  tree_->tree.setProbMiss(config_.prob_miss);
  return new_map;
}

#else  // no OctoMap in this build

struct OccupancyMap::Tree {};
bool occupancy_maps_available() { return false; }
OccupancyMap::OccupancyMap(const OccupancyMapConfig& config) : config_(config) {
  throw std::runtime_error("occupancy maps need OctoMap (liboctomap-dev); this build has none");
}
OccupancyIntegration OccupancyMap::integrate(const torch::Tensor&, const torch::Tensor&, const Camera&) { return {}; }
size_t OccupancyMap::nodes() const { return 0; }
int OccupancyMap::state_at(const Eigen::Vector3d&) const { return -1; }
size_t OccupancyMap::occupied_leaves() const { return 0; }
size_t OccupancyMap::free_leaves() const { return 0; }
OccupancyGrid2D OccupancyMap::project(double, double) const { return {}; }
void OccupancyMap::save(const std::string&) const {}
void OccupancyMap::clear() {}
bool OccupancyMap::set_config(const OccupancyMapConfig&) { return false; }

#endif

OccupancyMap::~OccupancyMap() = default;
OccupancyMap::OccupancyMap(OccupancyMap&&) noexcept = default;
OccupancyMap& OccupancyMap::operator=(OccupancyMap&&) noexcept = default;

}  // namespace umvs
