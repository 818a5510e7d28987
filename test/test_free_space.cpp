// A map that forgets what moved, on a rendered corridor: a box stands in it while the camera
// makes its first pass along the robot's path and is gone for the three passes after it. The
// streaming fusion must remove every point of the box and keep the static surfaces; the OctoMap
// must free the box's cells and keep the corridor's; a confidently wrong depth map and salt noise
// must not erase a wall.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <set>
#include <tuple>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/occupancy_map.h"

namespace umvs {
namespace {

SynthScene rendered_corridor() {
  SynthConfig cfg;
  cfg.scene = SynthSceneType::kCorridor;
  cfg.seed = 4;
  cfg.num_views = 5;  // a short drive down the corridor
  cfg.width = 160;
  cfg.height = 120;
  cfg.supersample = 1;
  cfg.lighting_change = false;
  cfg.gt_cloud_samples = 60000;
  return render_synthetic_scene(cfg);
}

struct Box {
  Eigen::Vector3d lo, hi;
  // Points of the box itself: inside it grown by `margin`.
  bool holds(const Eigen::Vector3f& p, double margin = 0.02) const {
    const Eigen::Vector3d q = p.cast<double>();
    return (q.array() >= lo.array() - margin).all() && (q.array() <= hi.array() + margin).all();
  }
};

// z-depth at which each pixel's ray enters the box (slab test), 0 where it misses.
torch::Tensor box_depth(const Camera& cam, const Box& box) {
  auto out = torch::zeros({cam.height, cam.width}, torch::kFloat32);
  auto o = out.accessor<float, 2>();
  const Eigen::Vector3d c = cam.center();
  const Eigen::Matrix3d to_world = cam.R().transpose() * cam.K.inverse();
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d dir = to_world * Eigen::Vector3d(u, v, 1.0);  // one unit of z-depth
      double t0 = 0, t1 = std::numeric_limits<double>::infinity();
      for (int k = 0; k < 3; ++k) {
        double a = (box.lo[k] - c[k]) / dir[k], b = (box.hi[k] - c[k]) / dir[k];
        if (a > b) std::swap(a, b);
        t0 = std::max(t0, a);
        t1 = std::min(t1, b);
      }
      if (t0 < t1 && t0 > 0) o[v][u] = static_cast<float>(t0);
    }
  }
  return out;
}

// The scene as the camera saw it with the box in it: the nearer surface wins.
torch::Tensor with_box(const SynthView& view, const Box& box) {
  const auto b = box_depth(view.camera, box);
  return torch::where((b > 0) & ((b < view.depth) | (view.depth <= 0)), b, view.depth);
}

// A 20 x 20 x 30 cm box at least 35 cm above the floor (on a stand the renderer does not draw)
// that every view of the path sees whole, each of its pixels well in front of the corridor (so that
// later rays pass through where it stood by more than the clearing margin).
Box place_box(const SynthScene& scene) {
  auto seen_by_all = [&](const Box& box) {
    for (const auto& view : scene.views) {
      const auto bd = box_depth(view.camera, box);
      const auto seen = bd > 0;
      if (seen.sum().item<int64_t>() < 50) return false;
      const int64_t H = view.camera.height, W = view.camera.width;
      if (seen.select(0, 0).any().item<bool>() || seen.select(0, H - 1).any().item<bool>() ||
          seen.select(1, 0).any().item<bool>() || seen.select(1, W - 1).any().item<bool>()) {
        return false;
      }
      // Clearly in front: every box pixel nearer than the corridor by more than the clearing margin.
      const double ratio = (view.depth.masked_select(seen) / bd.masked_select(seen)).min().item<float>();
      if (ratio < 1.02 + FusionConfig{}.clear_margin) return false;
    }
    return true;
  };
  for (const auto& anchor : scene.views) {
    auto d = anchor.depth.accessor<float, 2>();
    for (int v = anchor.camera.height / 4; v < 3 * anchor.camera.height / 4; v += 4) {
      for (int u = anchor.camera.width / 4; u < 3 * anchor.camera.width / 4; u += 4) {
        if (!(d[v][u] > 1.5f)) continue;
        for (double along : {0.3, 0.4, 0.5, 0.6, 0.7}) {
          const Eigen::Vector3d p = anchor.camera.backproject(u, v, along * d[v][u]);
          if (p.z() < 0.8 || p.z() > 1.3) continue;  // well above the floor, inside the grid's band
          const Box box{p - Eigen::Vector3d(0.15, 0.15, 0.2), p + Eigen::Vector3d(0.15, 0.15, 0.2)};
          if (seen_by_all(box)) return box;
        }
      }
    }
  }
  ADD_FAILURE() << "no place for the box in the rendered corridor";
  return {};
}

using PointKey = std::tuple<float, float, float>;
PointKey key(const Eigen::Vector3f& p) { return {p.x(), p.y(), p.z()}; }

FusionView estimate(const SynthView& v, const torch::Tensor& depth) {
  FusionView f;
  f.depth = depth;
  f.confidence = torch::ones_like(depth);
  f.camera = v.camera;
  return f;
}

StreamingFusion scene_fusion(int clear_after_views) {
  FusionConfig cfg;
  cfg.min_confidence = 0.5;
  cfg.min_agreeing_views = 2;
  cfg.clear_after_views = clear_after_views;
  return StreamingFusion(cfg, /*window=*/8, /*max_points=*/10000000, torch::kCPU);
}

TEST(FreeSpace, AnObjectThatLeftIsForgottenByTheCloudAndTheOctree) {
  const SynthScene scene = rendered_corridor();
  const Box box = place_box(scene);
  StreamingFusion fusion = scene_fusion(FusionConfig{}.clear_after_views);
  OccupancyMapConfig map_cfg;  // the fusion node's defaults, with every pixel a ray
  map_cfg.pixel_stride = 1;
  OccupancyMap map(map_cfg);
  const double band_min = 0.1, band_max = 1.5;  // the node's default height band

  // Occupied grid cells whose centre lies within half a cell of the box's footprint (the cells of
  // its faces; the inside of the box is never observed).
  auto occupied_under_box = [&] {
    const OccupancyGrid2D g = map.project(band_min, band_max);
    int n = 0;
    for (int j = 0; j < g.height; ++j) {
      for (int i = 0; i < g.width; ++i) {
        const double x = g.origin_x + (i + 0.5) * g.resolution, y = g.origin_y + (j + 0.5) * g.resolution;
        const double grow = 0.5 * g.resolution + 1e-6;
        const bool under = x > box.lo.x() - grow && x < box.hi.x() + grow && y > box.lo.y() - grow &&
                           y < box.hi.y() + grow;
        n += under && g.cells[static_cast<size_t>(j) * g.width + i] == 100;
      }
    }
    return n;
  };
  // Surface points of the corridor (not near the box) that the octree holds as occupied.
  auto static_points_occupied = [&] {
    std::vector<bool> occupied;
    for (const auto& p : scene.gt_cloud.points) occupied.push_back(!box.holds(p, 0.1) && map.state_at(p.cast<double>()) == 1);
    return occupied;
  };

  for (const auto& v : scene.views) {  // first pass: the box is there
    const auto depth = with_box(v, box);
    fusion.add(estimate(v, depth));
    map.integrate(depth, torch::Tensor(), v.camera);
  }
  std::set<PointKey> static_points;
  int64_t box_points = 0;
  for (const auto& p : fusion.cloud().points) {
    if (box.holds(p)) ++box_points;
    else static_points.insert(key(p));
  }
  const int box_cells = occupied_under_box();
  const std::vector<bool> static_before = static_points_occupied();
  ASSERT_GT(box_points, 300) << "the box is in the cloud after the first pass";
  ASSERT_GT(box_cells, 10) << "the box is in the grid after the first pass";

  // The box has gone: three more passes (15 looks). A point goes after clear_after_views looks
  // through it, an occupied cell at octomap's clamp after about nine rays.
  for (int pass = 0; pass < 3; ++pass) {
    for (const auto& v : scene.views) {
      fusion.add(estimate(v, v.depth));
      map.integrate(v.depth, torch::Tensor(), v.camera);
    }
  }
  int64_t box_left = 0;
  std::set<PointKey> now;
  for (const auto& p : fusion.cloud().points) {
    box_left += box.holds(p);
    now.insert(key(p));
  }
  int64_t static_kept = 0;
  for (const auto& p : static_points) static_kept += now.count(p);
  const double kept = static_cast<double>(static_kept) / static_points.size();
  const std::vector<bool> static_after = static_points_occupied();
  int64_t static_occupied = 0, static_still = 0;
  for (size_t i = 0; i < static_before.size(); ++i) {
    static_occupied += static_before[i];
    static_still += static_before[i] && static_after[i];
  }
  const double static_kept_cells = static_cast<double>(static_still) / static_occupied;
  std::printf("[ figures  ] box: %lld points and %d grid cells after the first pass, %lld and %d after three passes "
              "without it; static points kept %.2f %% of %zu (%lld removed in all); surface points of the corridor in occupied "
              "cells: %.2f %% of %lld still are\n",
              static_cast<long long>(box_points), box_cells, static_cast<long long>(box_left), occupied_under_box(),
              100 * kept, static_points.size(), static_cast<long long>(fusion.points_cleared()), 100 * static_kept_cells,
              static_cast<long long>(static_occupied));
  EXPECT_EQ(box_left, 0);
  EXPECT_EQ(occupied_under_box(), 0);
  EXPECT_GE(kept, 0.99);
  EXPECT_GE(static_kept_cells, 0.99);
}

TEST(FreeSpace, AConfidentlyWrongDepthMapAndSaltNoiseDoNotEraseWalls) {
  const SynthScene scene = rendered_corridor();
  // Every estimate is confident; one of them is 25 % too far everywhere (it sees "through" every
  // wall), and each has 3 % of its pixels at twice their depth.
  auto noisy = [&](size_t i) {
    auto depth = scene.views[i].depth.clone();
    if (i == 3) depth *= 1.25;
    torch::manual_seed(static_cast<uint64_t>(i));
    const auto salt = torch::rand(depth.sizes()) < 0.03;
    return torch::where(salt, 2 * depth, depth);
  };
  auto kept_share = [&](int clear_after_views) {
    StreamingFusion fusion = scene_fusion(clear_after_views);
    for (const auto& v : scene.views) fusion.add(estimate(v, v.depth));
    std::set<PointKey> before;
    for (const auto& p : fusion.cloud().points) before.insert(key(p));
    for (size_t i = 0; i < scene.views.size(); ++i) fusion.add(estimate(scene.views[i], noisy(i)));
    std::set<PointKey> after;
    for (const auto& p : fusion.cloud().points) after.insert(key(p));
    int64_t kept = 0;
    for (const auto& p : before) kept += after.count(p);
    return static_cast<double>(kept) / before.size();
  };
  const double with_rule = kept_share(FusionConfig{}.clear_after_views);
  const double one_look = kept_share(1);
  std::printf("[ figures  ] static points kept through a wrong map and salt noise: %.2f %% (one look clears: %.2f %%)\n",
              100 * with_rule, 100 * one_look);
  EXPECT_GE(with_rule, 0.99);
  EXPECT_LT(one_look, 0.9) << "without the rule, the wrong map erases walls (the test can tell)";
}

TEST(FreeSpace, EvidenceOfOnePoint) {
  Camera cam;
  cam.K << 10, 0, 4, 0, 10, 4, 0, 0, 1;
  cam.width = cam.height = 9;
  PointCloud cloud;
  cloud.points = {{0, 0, 2}, {0, 0, 4}, {0, 0, 1}, {100, 0, 2}};  // at 2 m (seen), behind, in front, outside
  auto depth = torch::full({9, 9}, 2.0f);
  auto valid = torch::ones({9, 9}, torch::kBool);
  auto e = free_space_evidence(cloud, depth, valid, cam, 0.05);
  EXPECT_EQ(e[0], FreeSpaceEvidence::kSeenAgain);
  EXPECT_EQ(e[1], FreeSpaceEvidence::kNone);        // hidden behind the surface
  EXPECT_EQ(e[2], FreeSpaceEvidence::kSeenThrough);  // the rays reach 2 m past it
  EXPECT_EQ(e[3], FreeSpaceEvidence::kNone);
  valid[5][5] = false;  // one pixel of the 3x3 is no estimate: no evidence either way
  e = free_space_evidence(cloud, depth, valid, cam, 0.05);
  EXPECT_EQ(e[2], FreeSpaceEvidence::kNone);
  EXPECT_THROW(cloud.erase({1}), std::invalid_argument);
  EXPECT_EQ(cloud.erase({0, 1, 0, 1}), 2u);
  EXPECT_EQ(cloud.points[1].z(), 1.0f);
}

}  // namespace
}  // namespace umvs
