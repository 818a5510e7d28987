// The OctoMap occupancy map against a rendered room's exact geometry: cells on its surfaces
// occupied, space between the cameras and the surfaces free, the .bt file read back by octomap
// itself and by octomap-tools, the 2-D projection of a height band, `umvs fuse --out map.bt`.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "cli_test_util.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/occupancy_map.h"

namespace umvs {
namespace {

SynthScene rendered_room() {
  SynthConfig cfg;
  cfg.scene = SynthSceneType::kRoom;
  cfg.seed = 4;
  cfg.num_views = 6;
  cfg.width = 160;
  cfg.height = 120;
  cfg.supersample = 1;
  cfg.lighting_change = false;
  cfg.gt_cloud_samples = 60000;
  return render_synthetic_scene(cfg);
}

struct Accuracy {
  double occupied = 0, free = 0;  // shares of surface points / points in front of surfaces classified right
};

// Surface points (the scene's ground-truth cloud) should be occupied; the points half-way from a
// camera to what it sees, free.
Accuracy classify(const OccupancyMap& map, const SynthScene& scene) {
  int64_t right = 0, total = 0;
  for (const auto& p : scene.gt_cloud.points) {
    const int s = map.state_at(p.cast<double>());
    if (s == -1) continue;  // not observed (beyond the rays' range or never in view)
    right += s == 1;
    ++total;
  }
  Accuracy a;
  a.occupied = static_cast<double>(right) / std::max<int64_t>(total, 1);
  right = total = 0;
  for (const auto& v : scene.views) {
    auto d = v.depth.accessor<float, 2>();
    for (int y = 3; y < v.camera.height; y += 7) {
      for (int x = 3; x < v.camera.width; x += 7) {
        if (!(d[y][x] > 0.6f)) continue;  // at least 30 cm of space in front of the surface
        right += map.state_at(v.camera.backproject(x, y, 0.5 * d[y][x])) == 0;
        ++total;
      }
    }
  }
  a.free = static_cast<double>(right) / std::max<int64_t>(total, 1);
  return a;
}

TEST(OccupancyMap, ExactDepthGivesTheRoomsSurfacesAndItsFreeSpace) {
  const SynthScene scene = rendered_room();
  OccupancyMapConfig cfg;
  cfg.resolution = 0.05;
  cfg.max_range = 10.0;
  OccupancyMap map(cfg);
  for (const auto& v : scene.views) EXPECT_GT(map.integrate(v.depth, torch::Tensor(), v.camera).rays, 10000);
  const Accuracy a = classify(map, scene);
  std::printf("[ figures  ] occupancy at 5 cm: %.1f %% of surface points occupied, %.1f %% of free points free\n",
              100 * a.occupied, 100 * a.free);
  EXPECT_GT(a.occupied, 0.8);  // 85.0 %: rays at grazing angles clear some cells of thin surfaces
  EXPECT_GT(a.free, 0.97);

  // The file is octomap's own: read back, the same tree.
  const std::string dir = test::temp_dir("occupancy");
  map.save(dir + "/room.bt");
  octomap::OcTree read(dir + "/room.bt");
  EXPECT_DOUBLE_EQ(read.getResolution(), 0.05);
  size_t occupied = 0;
  for (auto it = read.begin_leafs(); it != read.end_leafs(); ++it) occupied += read.isNodeOccupied(*it);
  EXPECT_EQ(occupied, map.occupied_leaves());
  // ... and octomap-tools open it.
  const auto converted = test::run_shell("convert_octree " + dir + "/room.bt " + dir + "/room.ot");
  EXPECT_EQ(converted.status, 0) << converted.output;
  EXPECT_TRUE(std::filesystem::exists(dir + "/room.ot"));

  // The 2-D grid of the band a ground robot cares about (the room's floor is at z = 0, its walls at
  // x = +-3 m, y = +-2.5 m): walls and furniture occupied, floor space free, beyond the walls
  // unknown; the grid is the extent's footprint.
  const OccupancyGrid2D grid = map.project(0.1, 1.5);
  ASSERT_EQ(grid.width, 1000);
  ASSERT_EQ(grid.height, 1000);
  EXPECT_DOUBLE_EQ(grid.origin_x, cfg.min_x);
  const auto cell = [&](double x, double y) {
    return grid.cells[static_cast<size_t>((y - grid.origin_y) / grid.resolution) * grid.width +
                      static_cast<size_t>((x - grid.origin_x) / grid.resolution)];
  };
  int occ = 0, fre = 0, unknown = 0;
  for (int8_t c : grid.cells) occ += c == 100, fre += c == 0, unknown += c == -1;
  EXPECT_GT(occ, 50);
  EXPECT_GT(fre, 50);
  EXPECT_EQ(occ + fre + unknown, 1000 * 1000);
  EXPECT_EQ(cell(4.0, 0.0), -1) << "behind a wall";
  EXPECT_EQ(cell(-20.0, 20.0), -1) << "never seen";
  int free_in_room = 0, occupied_outside = 0;
  for (double x = -2.5; x <= 2.5; x += 0.25) {
    for (double y = -2.0; y <= 2.0; y += 0.25) free_in_room += cell(x, y) == 0;
  }
  for (double x = 3.3; x < 25; x += 0.5) occupied_outside += cell(x, 0.0) == 100 || cell(-x, 0.0) == 100;
  EXPECT_GT(free_in_room, 100) << "of 357 sampled cells inside the room";
  EXPECT_EQ(occupied_outside, 0);
  EXPECT_THROW(map.project(1.0, 1.0), std::invalid_argument);

  // Pixels below the confidence floor cast no ray.
  OccupancyMap unsure(cfg);
  const auto& v = scene.views.front();
  EXPECT_EQ(unsure.integrate(v.depth, torch::full_like(v.depth, 0.2f), v.camera).rays, 0);
  EXPECT_EQ(unsure.occupied_leaves(), 0u);
}

// A camera 1.5 km away (a bad pose): skipped whole, said so, nothing allocated.
TEST(OccupancyMap, ACameraFarOutsideTheExtentIsSkippedWithoutAllocating) {
  const SynthScene scene = rendered_room();
  OccupancyMap map(OccupancyMapConfig{});
  Camera far = scene.views[0].camera;
  far.T_cam_world.topRightCorner<3, 1>() = far.t() - far.R() * Eigen::Vector3d(1500.0, 0.0, 0.0);  // 1.5 km along x
  ASSERT_NEAR(far.center().x(), scene.views[0].camera.center().x() + 1500.0, 1e-6);
  const OccupancyIntegration r = map.integrate(scene.views[0].depth, torch::Tensor(), far);
  EXPECT_TRUE(r.camera_outside);
  EXPECT_EQ(r.rays, 0);
  EXPECT_EQ(map.nodes(), 0u);
  EXPECT_FALSE(map.integrate(scene.views[0].depth, torch::Tensor(), scene.views[0].camera).camera_outside);
  EXPECT_GT(map.nodes(), 0u);
}

// A long random walk of cameras in and around a small box: every leaf stays inside it, rays that
// leave it are cut at its wall, the octree stops at its cap, and the grid keeps its size and origin,
// also through clear().
TEST(OccupancyMap, ALongRandomWalkStaysInsideItsBoxAndUnderItsNodeCap) {
  const SynthScene scene = rendered_room();
  OccupancyMapConfig cfg;
  cfg.resolution = 0.1;
  cfg.max_range = 4.0;
  cfg.pixel_stride = 2;
  cfg.min_x = -2.0, cfg.min_y = -1.5, cfg.min_z = 0.0, cfg.max_x = 1.0, cfg.max_y = 1.5, cfg.max_z = 2.0;
  cfg.max_nodes = 6000;
  OccupancyMap map(cfg);
  const OccupancyGrid2D empty = map.project(0.1, 1.5);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> step(-0.4, 0.4), turn(-0.3, 0.3);
  Eigen::Vector3d centre(0.0, 0.0, 1.2);
  int outside = 0, capped = 0, cut = 0;
  for (int i = 0; i < 300; ++i) {
    const auto& v = scene.views[static_cast<size_t>(i) % scene.views.size()];
    centre = (centre + Eigen::Vector3d(step(rng), step(rng), 0.5 * step(rng))).cwiseMax(Eigen::Vector3d(-3, -2.5, -0.5))
                 .cwiseMin(Eigen::Vector3d(2, 2.5, 2.5));
    Camera c = v.camera;
    const Eigen::Matrix3d R = v.camera.R() * Eigen::AngleAxisd(turn(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix().transpose();
    c.T_cam_world.topLeftCorner<3, 3>() = R;
    c.T_cam_world.topRightCorner<3, 1>() = -R * centre;
    const OccupancyIntegration r = map.integrate(v.depth, torch::Tensor(), c);
    outside += r.camera_outside;
    capped += r.at_node_cap;
    cut += r.cut > 0;
    // The last update allowed below the cap may split a pruned leaf down to full resolution:
    // at most 8 nodes on each of octomap's 16 levels.
    EXPECT_LE(map.nodes(), static_cast<size_t>(cfg.max_nodes) + 8 * 16) << "step " << i;
  }
  RecordProperty("outside", outside);
  RecordProperty("capped", capped);
  EXPECT_GT(outside, 0);
  EXPECT_GT(capped, 0);
  EXPECT_GT(cut, 100);
  // Every leaf inside the box (a leaf's centre within half a leaf of it).
  octomap::OcTree read(0.1);
  const std::string dir = test::temp_dir("occupancy_walk");
  map.save(dir + "/walk.bt");
  ASSERT_TRUE(read.readBinary(dir + "/walk.bt"));
  size_t leaves = 0, outside_leaves = 0;
  for (auto it = read.begin_leafs(); it != read.end_leafs(); ++it, ++leaves) {
    const Eigen::Vector3d p(it.getX(), it.getY(), it.getZ());
    const double h = it.getSize() / 2;
    outside_leaves += !(p.x() + h > cfg.min_x && p.x() - h < cfg.max_x && p.y() + h > cfg.min_y && p.y() - h < cfg.max_y &&
                        p.z() + h > cfg.min_z && p.z() - h < cfg.max_z);
  }
  EXPECT_GT(leaves, 100u);
  EXPECT_EQ(outside_leaves, 0u);
  // The grid: the box's footprint, before, now and after clear(); unknown again after it.
  const OccupancyGrid2D now = map.project(0.1, 1.5);
  map.clear();
  const OccupancyGrid2D cleared = map.project(0.1, 1.5);
  for (const OccupancyGrid2D* g : {&now, &cleared}) {
    EXPECT_EQ(g->width, 30);
    EXPECT_EQ(g->height, 30);
    EXPECT_EQ(g->origin_x, empty.origin_x);
    EXPECT_EQ(g->origin_y, empty.origin_y);
  }
  EXPECT_NE(now.cells, empty.cells);
  EXPECT_EQ(cleared.cells, empty.cells);
  EXPECT_EQ(std::count(empty.cells.begin(), empty.cells.end(), -1), 900);
}

// Depth beyond max_range is never a hit: the ray only clears up to it.
TEST(OccupancyMap, DepthBeyondTheRangeLimitOnlyClears) {
  const SynthScene scene = rendered_room();
  OccupancyMapConfig cfg;
  cfg.max_range = 1.0;
  OccupancyMap map(cfg);
  const auto& v = scene.views[0];
  const OccupancyIntegration r = map.integrate(v.depth, torch::Tensor(), v.camera);
  EXPECT_GT(r.cut, r.rays / 2) << "the room's surfaces are mostly farther than 1 m";
  const std::string dir = test::temp_dir("occupancy_range");
  map.save(dir + "/range.bt");
  octomap::OcTree read(0.05);
  ASSERT_TRUE(read.readBinary(dir + "/range.bt"));
  double farthest_hit = 0.0;
  for (auto it = read.begin_leafs(); it != read.end_leafs(); ++it) {
    if (read.isNodeOccupied(*it)) {
      farthest_hit = std::max(farthest_hit, (Eigen::Vector3d(it.getX(), it.getY(), it.getZ()) - v.camera.center()).norm());
    }
  }
  EXPECT_LT(farthest_hit, 1.0 + 0.05);
}

TEST(OccupancyMap, BadSettingsAreRefusedByName) {
  OccupancyMapConfig cfg;
  cfg.resolution = 0;
  EXPECT_THROW(OccupancyMap{cfg}, std::invalid_argument);
  cfg = {};
  cfg.prob_hit = 0.4;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
  for (const auto& [field, broken] : std::vector<std::pair<std::string, OccupancyMapConfig>>{
           {"extent", [] { OccupancyMapConfig c; c.max_x = c.min_x; return c; }()},
           {"extent", [] { OccupancyMapConfig c; c.max_z = std::nan(""); return c; }()},
           {"address", [] { OccupancyMapConfig c; c.resolution = 0.01; c.max_x = 400; return c; }()},
           {"max_nodes", [] { OccupancyMapConfig c; c.max_nodes = 0; return c; }()}}) {
    try {
      broken.validate();
      ADD_FAILURE() << field << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  }
}

TEST(OccupancyMap, FuseWritesABtFile) {
  const std::string dir = test::scene("occupancy_fuse");
  const std::string out = test::temp_dir("occupancy_fuse_out");
  // The scene's exact depth as the estimates (depth_gt/ of the folder, confidence 1).
  const auto r = test::run_umvs("fuse --depth " + dir + "/depth_gt --data " + dir + " --out " + out + "/map.bt --octomap-resolution 0.1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(test::contains(r.output, "occupied")) << r.output;
  octomap::OcTree read(out + "/map.bt");
  EXPECT_DOUBLE_EQ(read.getResolution(), 0.1);
  EXPECT_GT(read.getNumLeafNodes(), 100u);
}

}  // namespace
}  // namespace umvs
