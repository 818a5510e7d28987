#include "unsup_mvs/io/occupancy_map.h"

#include <torch/torch.h>

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

int64_t OccupancyMap::integrate(const torch::Tensor& depth, const torch::Tensor& confidence, const Camera& camera) {
  if (depth.dim() != 2 || depth.size(0) != camera.height || depth.size(1) != camera.width) {
    throw std::invalid_argument("occupancy map: the depth map must be [H,W] of its camera's size");
  }
  if (confidence.defined() && confidence.sizes() != depth.sizes()) {
    throw std::invalid_argument("occupancy map: confidence and depth differ in size");
  }
  const auto d = depth.to(torch::kFloat32).contiguous();
  const auto c = confidence.defined() ? confidence.to(torch::kFloat32).contiguous() : torch::ones_like(d);
  const auto da = d.accessor<float, 2>();
  const auto ca = c.accessor<float, 2>();
  const Eigen::Vector3d origin = camera.center();
  octomap::Pointcloud hits;
  for (int64_t v = 0; v < d.size(0); v += config_.pixel_stride) {
    for (int64_t u = 0; u < d.size(1); u += config_.pixel_stride) {
      const float z = da[v][u];
      if (!(z > 0.0f) || !std::isfinite(z) || ca[v][u] < config_.min_confidence) continue;
      const Eigen::Vector3d p = camera.backproject(static_cast<double>(u), static_cast<double>(v), z);
      hits.push_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
    }
  }
  // Rays longer than max_range mark free space up to it and no hit (octomap's maxrange).
  tree_->tree.insertPointCloud(hits, octomap::point3d(origin.x(), origin.y(), origin.z()), config_.max_range,
                               /*lazy_eval=*/false, /*discretize=*/true);
  return static_cast<int64_t>(hits.size());
}

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
  double x0, y0, z0, x1, y1, z1;
  tree_->tree.getMetricMin(x0, y0, z0);
  tree_->tree.getMetricMax(x1, y1, z1);
  if (tree_->tree.size() == 0 || !(x1 > x0) || !(y1 > y0)) return grid;
  grid.origin_x = std::floor(x0 / grid.resolution) * grid.resolution;
  grid.origin_y = std::floor(y0 / grid.resolution) * grid.resolution;
  grid.width = static_cast<int>(std::ceil((x1 - grid.origin_x) / grid.resolution));
  grid.height = static_cast<int>(std::ceil((y1 - grid.origin_y) / grid.resolution));
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
  const bool new_resolution = config.resolution != config_.resolution;
  config_ = config;
  if (new_resolution) tree_ = std::make_unique<Tree>(config_.resolution);
  tree_->tree.setProbHit(config_.prob_hit);
  tree_->tree.setProbMiss(config_.prob_miss);
  return new_resolution;
}

#else  // no OctoMap in this build

struct OccupancyMap::Tree {};
bool occupancy_maps_available() { return false; }
OccupancyMap::OccupancyMap(const OccupancyMapConfig& config) : config_(config) {
  throw std::runtime_error("occupancy maps need OctoMap (liboctomap-dev); this build has none");
}
int64_t OccupancyMap::integrate(const torch::Tensor&, const torch::Tensor&, const Camera&) { return 0; }
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
