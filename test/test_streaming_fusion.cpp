// Streaming fusion (core/fusion.h StreamingFusion), estimate by estimate, on the analytic scene of
// fusion_test_fixtures.h: it agrees with batch fusion, confirms early views later, bounds its
// memory and takes new thresholds from the next view on.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
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

TEST(StreamingFusion, AgreesWithBatchFusion) {
  auto views = ring_views(6);
  FusionConfig cfg;
  auto batch = DepthFusion(cfg, torch::kCPU).fuse(views, all_others(views.size()));
  StreamingFusion stream(cfg, 6, 1000000, torch::kCPU);
  size_t streamed = 0;
  for (const auto& v : views) streamed += stream.add(v).size();
  EXPECT_EQ(stream.num_views(), 6u);
  EXPECT_EQ(streamed, stream.cloud().size());
  ASSERT_EQ(stream.cloud().size(), batch.size());  // the same pixels survive
  // The same points, up to averaging over fewer views at emission time.
  auto d = torch::cdist(to_tensor(stream.cloud()), to_tensor(batch)).amin(1);
  EXPECT_LT(d.median().item<double>(), 1e-4);
  EXPECT_LT(d.max().item<double>(), 0.01);
  expect_accurate(to_tensor(stream.cloud()));
  EXPECT_GE(*std::min_element(stream.cloud().num_views.begin(), stream.cloud().num_views.end()), 3);
}

TEST(StreamingFusion, FirstViewsConfirmedLaterAndWindowBoundsMemory) {
  auto views = ring_views(8);
  FusionConfig cfg;
  StreamingFusion stream(cfg, 3, 1000000, torch::kCPU);
  // Nothing can be confirmed before 4 estimates exist (3 agreeing others needed).
  EXPECT_EQ(stream.add(views[0]).size(), 0u);
  EXPECT_EQ(stream.add(views[1]).size(), 0u);
  EXPECT_EQ(stream.add(views[2]).size(), 0u);
  auto fourth = stream.add(views[3]);
  EXPECT_GT(fourth.size(), 1000u);  // all four views' shared pixels at once
  EXPECT_EQ(stream.num_views(), 3u);  // the ring holds `window` estimates
  for (size_t i = 4; i < views.size(); ++i) stream.add(views[i]);
  EXPECT_EQ(stream.num_views(), 3u);
  expect_accurate(to_tensor(stream.cloud()));
  stream.reset();
  EXPECT_EQ(stream.num_views(), 0u);
  EXPECT_TRUE(stream.cloud().empty());
}

TEST(StreamingFusion, VoxelHashAndPointLimitBoundTheCloud) {
  auto views = ring_views(8);
  FusionConfig cfg;
  cfg.voxel_size = 0.03;
  StreamingFusion stream(cfg, 8, 1000000, torch::kCPU);
  for (const auto& v : views) stream.add(v);
  std::set<std::tuple<int64_t, int64_t, int64_t>> cells;
  for (const auto& p : stream.cloud().points) {
    EXPECT_TRUE(cells.insert({int64_t(std::floor(p.x() / 0.03)), int64_t(std::floor(p.y() / 0.03)), int64_t(std::floor(p.z() / 0.03))}).second);
  }
  const size_t full = stream.cloud().size();
  ASSERT_GT(full, 200u);
  StreamingFusion small(cfg, 8, 100, torch::kCPU);
  for (const auto& v : views) {
    small.add(v);
    EXPECT_LE(small.cloud().size(), 100u);
  }
  EXPECT_GT(small.cloud().size(), 50u);
}

TEST(StreamingFusion, BadViewLeavesStateUnchanged) {
  auto views = ring_views(4);
  StreamingFusion stream(FusionConfig{}, 4, 1000000, torch::kCPU);
  for (const auto& v : views) stream.add(v);
  const size_t n = stream.cloud().size();
  auto bad = views[0];
  bad.color = torch::zeros({10, 10, 3}, torch::kUInt8);
  EXPECT_THROW(stream.add(bad), std::invalid_argument);
  EXPECT_EQ(stream.num_views(), 4u);
  EXPECT_EQ(stream.cloud().size(), n);
}

TEST(StreamingFusion, NewThresholdsApplyFromTheNextView) {
  auto views = ring_views(8);
  FusionConfig cfg;  // 3 agreeing views
  StreamingFusion stream(cfg, 8, 1000000, torch::kCPU);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(stream.add(views[i]).size(), 0u);

  // Invalid: refused, nothing changed.
  FusionConfig bad = cfg;
  bad.max_reprojection_px = 0;
  EXPECT_THROW(stream.set_config(bad), std::invalid_argument);
  EXPECT_DOUBLE_EQ(stream.config().max_reprojection_px, cfg.max_reprojection_px);

  // A stricter rule: the fourth view, which confirms the shared pixels at 3 views, adds nothing.
  FusionConfig strict = cfg;
  strict.min_agreeing_views = 5;
  stream.set_config(strict);
  EXPECT_EQ(stream.config().min_agreeing_views, 5);
  EXPECT_EQ(stream.add(views[3]).size(), 0u);
  // Back to 3: the next view emits the pixels the four stored ones already agree on, and more.
  stream.set_config(cfg);
  EXPECT_GT(stream.add(views[4]).size(), 1000u);
  expect_accurate(to_tensor(stream.cloud()));

  // A voxel grid from now on: the next view adds only points in voxels not yet taken, and fewer
  // than the same stream without the grid adds.
  StreamingFusion plain(cfg, 8, 1000000, torch::kCPU);
  for (int i = 0; i < 5; ++i) plain.add(views[i]);
  FusionConfig voxels = cfg;
  voxels.voxel_size = 0.03;
  stream.set_config(voxels);
  std::set<std::tuple<int64_t, int64_t, int64_t>> taken;
  auto cell = [](const Eigen::Vector3f& p) {
    return std::make_tuple(int64_t(std::floor(p.x() / 0.03)), int64_t(std::floor(p.y() / 0.03)),
                           int64_t(std::floor(p.z() / 0.03)));
  };
  for (const auto& p : stream.cloud().points) taken.insert(cell(p));
  const PointCloud without_grid = plain.add(views[5]);
  const PointCloud with_grid = stream.add(views[5]);
  ASSERT_GT(without_grid.size(), 100u);
  EXPECT_LT(with_grid.size(), without_grid.size());
  for (const auto& p : with_grid.points) EXPECT_TRUE(taken.insert(cell(p)).second);
}

}  // namespace
}  // namespace umvs
