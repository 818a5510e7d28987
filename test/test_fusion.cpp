// Depth-map fusion on an analytic scene: a ground plane z = 0 with a sphere on it, seen by a ring
// of cameras (fusion_test_fixtures.h). Ground-truth depth maps are ray-cast there, so every fused
// point can be checked against the exact surface. Streaming fusion: test_streaming_fusion.cpp.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <set>
#include <tuple>

#include "fusion_test_fixtures.h"
#include "unsup_mvs/core/fusion.h"

namespace umvs {
namespace {

using test::all_others;
using test::expect_accurate;
using test::ring_views;
using test::to_tensor;

// Share of `truth` points [M,3] with a cloud point within `tol`.
double completeness(const torch::Tensor& cloud, const torch::Tensor& truth, double tol) {
  auto d = torch::cdist(truth, cloud).amin(1);
  return (d < tol).to(torch::kFloat64).mean().item<double>();
}

// Ground-truth surface samples: every 3rd pixel of every view, back-projected.
torch::Tensor truth_points(const std::vector<FusionView>& views) {
  std::vector<float> xyz;
  for (const auto& v : views) {
    auto d = v.depth.accessor<float, 2>();
    for (int y = 1; y < v.camera.height; y += 3)
      for (int x = 1; x < v.camera.width; x += 3)
        if (d[y][x] > 0) {
          const Eigen::Vector3d p = v.camera.backproject(x, y, d[y][x]);
          xyz.insert(xyz.end(), {float(p.x()), float(p.y()), float(p.z())});
        }
  }
  return torch::tensor(xyz).view({-1, 3});
}

TEST(DepthFusion, GroundTruthDepthGivesAnAccurateAndCompleteCloud) {
  auto views = ring_views();
  std::vector<FusionViewStats> stats;
  DepthFusion fusion(FusionConfig{}, torch::kCPU);
  auto cloud = fusion.fuse(views, {}, &stats);
  ASSERT_GT(cloud.size(), 5000u);
  ASSERT_EQ(stats.size(), views.size());
  auto pts = to_tensor(cloud);
  expect_accurate(pts);
  // Most of what at least 4 views see is reconstructed: the outermost views of the half ring see
  // parts of the plane no other 3 views see, so completeness is measured on the inner views.
  auto truth = truth_points({views.begin() + 2, views.end() - 2});
  EXPECT_GT(completeness(pts, truth, 0.01), 0.8);
  ASSERT_EQ(cloud.num_views.size(), cloud.size());
  ASSERT_EQ(cloud.confidence.size(), cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    EXPECT_GE(cloud.num_views[i], 3);
    EXPECT_LE(cloud.num_views[i], 7);
    EXPECT_FLOAT_EQ(cloud.confidence[i], 1.0f);
  }
  int64_t total = 0;
  for (const auto& s : stats) {
    total += s.points;
    EXPECT_LE(s.num_sources, 7);
    EXPECT_GE(s.num_sources, 3);
  }
  EXPECT_EQ(total, static_cast<int64_t>(cloud.size()));
}

TEST(DepthFusion, ZeroRequiredViewsKeepsEveryValidPixel) {
  auto views = ring_views(4);
  views[1].depth[5][7] = std::numeric_limits<float>::quiet_NaN();
  views[2].depth[0][0] = -1.0f;
  int64_t valid = 0;
  for (const auto& v : views) valid += (torch::isfinite(v.depth) & (v.depth > 0)).sum().item<int64_t>();
  FusionConfig cfg;
  cfg.min_agreeing_views = 0;
  auto cloud = DepthFusion(cfg, torch::kCPU).fuse(views);
  EXPECT_EQ(static_cast<int64_t>(cloud.size()), valid);
  expect_accurate(to_tensor(cloud));
}

TEST(DepthFusion, ViewCountThresholdIsMonotoneAndHonoured) {
  auto views = ring_views();
  size_t previous = std::numeric_limits<size_t>::max();
  for (int k : {1, 2, 3, 5, 7, 8}) {
    FusionConfig cfg;
    cfg.min_agreeing_views = k;
    auto cloud = DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()));
    EXPECT_LE(cloud.size(), previous) << "k=" << k;
    previous = cloud.size();
    for (auto n : cloud.num_views) ASSERT_GE(n, k);
    if (k == 8) {
      EXPECT_EQ(cloud.size(), 0u);  // only 7 other views exist
    }
    if (k == 7) {
      EXPECT_GT(cloud.size(), 0u);  // the sphere top is seen by all
    }
  }
}

TEST(DepthFusion, CorruptedViewIsRemovedWhileTheOthersSurvive) {
  auto views = ring_views();
  std::vector<FusionViewStats> clean, offset, noisy;
  DepthFusion fusion(FusionConfig{}, torch::kCPU);
  fusion.fuse(views, all_others(views.size()), &clean);

  auto corrupted = views;
  corrupted[3].depth = views[3].depth * 1.05;  // 5% too far: about 10 cm
  auto cloud = fusion.fuse(corrupted, all_others(views.size()), &offset);
  // A handful of pixels where interpolated source depths happen to match may survive.
  EXPECT_LT(offset[3].points, 0.01 * clean[3].points);
  expect_accurate(to_tensor(cloud));
  // The other views lose one possible witness but keep most points.
  for (size_t i = 0; i < views.size(); ++i) {
    if (i != 3) {
      EXPECT_GT(offset[i].points, 0.7 * clean[i].points) << "view " << i;
    }
  }

  torch::manual_seed(0);
  corrupted[3].depth = views[3].depth * (1.0 + 0.05 * torch::randn_like(views[3].depth));
  cloud = fusion.fuse(corrupted, all_others(views.size()), &noisy);
  // Only pixels whose noise happens to be < 1% can agree with the others (about 16% of them).
  EXPECT_LT(noisy[3].points, 0.3 * clean[3].points);
  EXPECT_GT(noisy[3].points, 0.05 * clean[3].points);
  // ... and those lie within 1% of the surface.
  expect_accurate(to_tensor(cloud), 2e-4, 0.01);
}

TEST(DepthFusion, RelativeDepthThresholdDecides) {
  auto views = ring_views();
  views[3].depth = views[3].depth * 1.005;  // 0.5% too far
  std::vector<FusionViewStats> loose, tight;
  FusionConfig cfg;
  DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()), &loose);
  cfg.max_relative_depth = 0.002;
  DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()), &tight);
  EXPECT_GT(loose[3].points, 0.8 * loose[2].points);
  EXPECT_LT(tight[3].points, 0.1 * loose[3].points);
  EXPECT_GT(tight[2].points, 0.6 * loose[2].points);
}

TEST(DepthFusion, ReprojectionThresholdDecides) {
  // View 3 20% too far, with the depth test switched off: a source reads the true surface where
  // the wrong point projects, and that surface point lands several pixels (parallax) away.
  auto views = ring_views();
  views[3].depth = views[3].depth * 1.2;
  std::vector<FusionViewStats> tight, loose;
  FusionConfig cfg;
  cfg.max_relative_depth = 1.0;  // isolate the pixel test
  DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()), &tight);
  cfg.max_reprojection_px = 20.0;
  DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()), &loose);
  EXPECT_LT(tight[3].points, 0.1 * tight[2].points);
  EXPECT_GT(loose[3].points, 0.5 * loose[2].points);
}

TEST(DepthFusion, ConfidenceThresholdDropsUnsurePixels) {
  auto views = ring_views();
  for (auto& v : views) v.confidence = torch::ones_like(v.depth);
  // View 0: left half 0.5, right half 0.9.
  views[0].confidence.slice(1, 0, 32).fill_(0.5);
  views[0].confidence.slice(1, 32, 64).fill_(0.9);
  auto count_conf = [](const PointCloud& c, float value) {
    return std::count_if(c.confidence.begin(), c.confidence.end(), [&](float x) { return std::abs(x - value) < 1e-6; });
  };
  FusionConfig cfg;  // 0.8
  auto strict = DepthFusion(cfg, torch::kCPU).fuse(views);
  EXPECT_EQ(count_conf(strict, 0.5f), 0);
  EXPECT_GT(count_conf(strict, 0.9f), 100);
  cfg.min_confidence = 0.4;
  auto lax = DepthFusion(cfg, torch::kCPU).fuse(views);
  EXPECT_GT(count_conf(lax, 0.5f), 100);
  EXPECT_GT(lax.size(), strict.size());
  cfg.min_confidence = 0.95;  // view 0 drops out entirely
  auto none = DepthFusion(cfg, torch::kCPU).fuse(views);
  EXPECT_EQ(count_conf(none, 0.9f) + count_conf(none, 0.5f), 0);
}

TEST(DepthFusion, VoxelGridRemovesDuplicates) {
  auto views = ring_views();
  FusionConfig cfg;
  auto dense = DepthFusion(cfg, torch::kCPU).fuse(views);
  cfg.voxel_size = 0.03;
  auto sparse = DepthFusion(cfg, torch::kCPU).fuse(views);
  EXPECT_LT(sparse.size(), dense.size() / 2);
  std::set<std::tuple<int64_t, int64_t, int64_t>> cells;
  for (const auto& p : sparse.points) {
    auto cell = std::make_tuple(int64_t(std::floor(p.x() / 0.03)), int64_t(std::floor(p.y() / 0.03)), int64_t(std::floor(p.z() / 0.03)));
    EXPECT_TRUE(cells.insert(cell).second) << "two points in one voxel";
  }
  // Still covers the scene at voxel resolution.
  EXPECT_GT(completeness(to_tensor(sparse), to_tensor(dense), 0.03), 0.95);
}

TEST(DepthFusion, RejectsBadInput) {
  auto views = ring_views(3);
  views[1].camera.width = 32;
  EXPECT_THAT([&] { DepthFusion(FusionConfig{}, torch::kCPU).fuse(views); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("view 1")));
  views = ring_views(3);
  EXPECT_THROW(DepthFusion(FusionConfig{}, torch::kCPU).fuse(views, {{1}, {0}}), std::invalid_argument);
  EXPECT_THROW(DepthFusion(FusionConfig{}, torch::kCPU).fuse(views, {{0}, {0}, {0}}), std::invalid_argument);
  FusionConfig bad;
  bad.max_relative_depth = 0;
  EXPECT_THROW(DepthFusion(bad, torch::kCPU), std::invalid_argument);
  bad = FusionConfig{};
  bad.min_confidence = 1.5;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  EXPECT_THROW(StreamingFusion(FusionConfig{}, 0, 100, torch::kCPU), std::invalid_argument);
}

TEST(DepthFusion, PerPixelLoopMatchesTensorOps) {
  // The CPU loop (check_consistency) and the torch-op version used on CUDA, on noisy depth with
  // holes and mixed confidence, for both source rules.
  torch::manual_seed(11);
  auto views = ring_views();
  for (auto& v : views) {
    v.depth = v.depth * (1 + 0.004 * torch::randn_like(v.depth));
    v.depth.masked_fill_(torch::rand_like(v.depth) < 0.05, 0.0f);
    v.confidence = torch::rand_like(v.depth);
  }
  for (const auto rule : {FusionSourceRule::kConfidentNeighbours, FusionSourceRule::kMvsnetEval}) {
    FusionConfig cfg;
    cfg.min_confidence = 0.3;
    cfg.source_rule = rule;
    for (const auto& [r, s] : std::vector<std::pair<int, int>>{{0, 1}, {0, 3}, {5, 4}}) {
      const auto& ref = views[r];
      const auto& src = views[s];
      auto ref_valid = valid_estimate_mask(ref.depth, ref.confidence, cfg.min_confidence);
      auto src_valid = valid_estimate_mask(src.depth, src.confidence, cfg.min_confidence);
      auto loop = check_consistency(ref.depth, ref_valid, ref.camera, src.depth, src_valid, src.camera, cfg);
      auto ops = check_consistency_tensor_ops(ref.depth, ref_valid, ref.camera, src.depth, src_valid, src.camera, cfg);
      const int64_t n_loop = loop.agree.sum().item<int64_t>(), n_ops = ops.agree.sum().item<int64_t>();
      const int64_t differ = (loop.agree != ops.agree).sum().item<int64_t>();
      auto both = loop.agree & ops.agree;
      auto depth_diff = ((loop.depth - ops.depth).abs() / ref.depth).masked_select(both);
      // Where float32 and float64 coordinates round to different 1/32 pixels (mvsnet rule), d'
      // moves with the depth gradient: a rare event, allowed as for borderline agreement.
      const int64_t depth_differ = (depth_diff > 1e-5).sum().item<int64_t>();
      std::cout << "[fusion] rule " << to_string(rule) << " views " << r << "/" << s << ": " << n_loop << " agree (loop), "
                << n_ops << " (tensor ops), " << differ << " differ, " << depth_differ
                << " with d' differing by > 1e-5 (median difference " << depth_diff.median().item<double>() << ")\n";
      EXPECT_GT(n_loop, 150);
      EXPECT_LE(differ, 3 + n_loop / 500);  // borderline pixels: float32 vs float64 geometry
      EXPECT_LE(depth_differ, 3 + n_loop / 500);
      EXPECT_LT(depth_diff.median().item<double>(), 1e-6);
    }
  }
}

TEST(DepthFusion, MvsnetRuleCountsUnconfidentSources) {
  // Only view 0 is confident. The default rule needs confident source pixels, so nothing
  // survives; MVSNet's eval.py rule reads the sources' depth whatever their confidence.
  auto views = ring_views();
  for (auto& v : views) v.confidence = torch::full_like(v.depth, 0.5);
  views[0].confidence.fill_(1.0);
  FusionConfig cfg;
  const auto sources = all_others(views.size());
  std::vector<FusionViewStats> neighbours_stats, mvsnet_stats;
  EXPECT_EQ(DepthFusion(cfg, torch::kCPU).fuse(views, sources, &neighbours_stats).size(), 0u);
  cfg.source_rule = FusionSourceRule::kMvsnetEval;
  const PointCloud mvsnet = DepthFusion(cfg, torch::kCPU).fuse(views, sources, &mvsnet_stats);
  EXPECT_EQ(static_cast<int64_t>(mvsnet.size()), mvsnet_stats[0].points);
  EXPECT_GT(mvsnet_stats[0].points, 0.5 * mvsnet_stats[0].valid_pixels);
  expect_accurate(to_tensor(mvsnet));
  // With everything confident both rules keep about the same pixels of view 0.
  for (auto& v : views) v.confidence.fill_(1.0);
  std::vector<FusionViewStats> all_confident;
  cfg.source_rule = FusionSourceRule::kConfidentNeighbours;
  DepthFusion(cfg, torch::kCPU).fuse(views, sources, &all_confident);
  EXPECT_NEAR(static_cast<double>(mvsnet_stats[0].points), static_cast<double>(all_confident[0].points),
              0.1 * all_confident[0].points);
}

TEST(DepthFusion, MvsnetRuleReadsTheSourceLikeCv2Remap) {
  // Reference and source 5 cm apart along x, reference depth 2.1 m everywhere: reference pixel x
  // lands on source column u = x - f b / d = x - 1.190476. The source depth is a ramp along its
  // columns, so the depth read there (which, for a pure x translation, is the d' returned) tells
  // how it was interpolated: at u (default rule) or at u rounded to 1/32 pixel (cv2.remap).
  const int W = 64, H = 48;
  const double f = 50, b = 0.05, d = 2.1, slope = 0.01;
  Camera ref;
  ref.width = W;
  ref.height = H;
  ref.K << f, 0, 31.5, 0, f, 23.5, 0, 0, 1;
  Camera src = ref;
  src.T_cam_world(0, 3) = -b;
  auto ref_depth = torch::full({H, W}, static_cast<float>(d));
  auto src_depth = (d + slope * (torch::arange(W, torch::kFloat64) - 32)).to(torch::kFloat32).view({1, W}).expand({H, W}).contiguous();
  FusionConfig cfg;
  cfg.max_relative_depth = 0.5;
  cfg.max_reprojection_px = 5.0;
  auto valid = torch::ones({H, W}, torch::kBool);
  const auto exact = check_consistency(ref_depth, valid, ref, src_depth, valid, src, cfg);
  cfg.source_rule = FusionSourceRule::kMvsnetEval;
  const auto remap = check_consistency(ref_depth, valid, ref, src_depth, valid, src, cfg);
  const double u_frac = 10 - f * b / d;  // column 10
  const double u_grid = std::nearbyint(u_frac * 32) / 32;
  ASSERT_TRUE(exact.agree[20][10].item<bool>());
  ASSERT_TRUE(remap.agree[20][10].item<bool>());
  EXPECT_NEAR(exact.depth[20][10].item<double>(), d + slope * (u_frac - 32), 1e-6);
  EXPECT_NEAR(remap.depth[20][10].item<double>(), d + slope * (u_grid - 32), 1e-6);
  EXPECT_GT(std::abs(u_grid - u_frac) * slope, 2e-5);  // the two readings differ measurably
  // Column 0 lands left of the source image (u = -1.19): no depth there with the default rule;
  // cv2.remap reads 0 beyond the border, which the round trip then rejects.
  EXPECT_FALSE(exact.agree[20][0].item<bool>());
  EXPECT_FALSE(remap.agree[20][0].item<bool>());
}

TEST(DepthFusion, CudaMatchesCpu) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device: CUDA fusion test skipped";
  auto views = ring_views();
  auto cpu = DepthFusion(FusionConfig{}, torch::kCPU).fuse(views, all_others(views.size()));
  auto gpu = DepthFusion(FusionConfig{}, torch::kCUDA).fuse(views, all_others(views.size()));
  EXPECT_NEAR(static_cast<double>(gpu.size()), static_cast<double>(cpu.size()), 0.002 * cpu.size());
  expect_accurate(to_tensor(gpu));
}

}  // namespace
}  // namespace umvs
