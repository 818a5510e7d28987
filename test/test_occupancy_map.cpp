// The OctoMap occupancy map against a rendered room's exact geometry: cells on its surfaces
// occupied, space between the cameras and the surfaces free, the .bt file read back by octomap
// itself and by octomap-tools, the 2-D projection of a height band, `umvs fuse --out map.bt`.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>
#include <torch/torch.h>

#include <filesystem>

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
  for (const auto& v : scene.views) EXPECT_GT(map.integrate(v.depth, torch::Tensor(), v.camera), 10000);
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

  // The 2-D grid of a band above the floor: walls and furniture occupied, floor space free.
  const OccupancyGrid2D grid = map.project(-10.0, 10.0);
  ASSERT_GT(grid.width, 0);
  int occ = 0, fre = 0;
  for (int8_t c : grid.cells) occ += c == 100, fre += c == 0;
  EXPECT_GT(occ, 50);
  EXPECT_GT(fre, 50);
  EXPECT_THROW(map.project(1.0, 1.0), std::invalid_argument);

  // Pixels below the confidence floor cast no ray.
  OccupancyMap unsure(cfg);
  const auto& v = scene.views.front();
  EXPECT_EQ(unsure.integrate(v.depth, torch::full_like(v.depth, 0.2f), v.camera), 0);
  EXPECT_EQ(unsure.occupied_leaves(), 0u);
}

TEST(OccupancyMap, BadSettingsAreRefusedByName) {
  OccupancyMapConfig cfg;
  cfg.resolution = 0;
  EXPECT_THROW(OccupancyMap{cfg}, std::invalid_argument);
  cfg = {};
  cfg.prob_hit = 0.4;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
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
