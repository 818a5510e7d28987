#include <gtest/gtest.h>
#include <torch/torch.h>

#include "unsup_mvs/core/metrics.h"

namespace umvs {
namespace {

// A 1 mm grid on the plane z = 0, 150 x 150 points.
PointCloud plane_grid(double z = 0.0) {
  PointCloud c;
  for (int i = 0; i < 150; ++i)
    for (int j = 0; j < 150; ++j) c.points.emplace_back(i * 0.001f, j * 0.001f, static_cast<float>(z));
  return c;
}

TEST(CloudMetrics, CloudAgainstItselfIsPerfect) {
  const PointCloud gt = plane_grid();
  const CloudMetrics m = evaluate_cloud(gt, gt);
  EXPECT_EQ(m.accuracy_mean, 0.0);
  EXPECT_EQ(m.completeness_mean, 0.0);
  EXPECT_EQ(m.overall, 0.0);
  ASSERT_EQ(m.fscore.size(), 3u);
  for (double f : m.fscore) EXPECT_DOUBLE_EQ(f, 1.0);
}

TEST(CloudMetrics, ShiftedCopyGivesTheShift) {
  const double d = 0.0035;
  const CloudMetrics m = evaluate_cloud(plane_grid(d), plane_grid());
  EXPECT_NEAR(m.accuracy_mean, d, 1e-6);
  EXPECT_NEAR(m.accuracy_median, d, 1e-6);
  EXPECT_NEAR(m.completeness_mean, d, 1e-6);
  EXPECT_NEAR(m.overall, d, 1e-6);
  // Thresholds 2, 5 and 10 mm: nothing within 2 mm, everything within 5 mm.
  EXPECT_DOUBLE_EQ(m.precision[0], 0.0);
  EXPECT_DOUBLE_EQ(m.recall[1], 1.0);
  EXPECT_DOUBLE_EQ(m.fscore[2], 1.0);
  // The outlier cap drops distances beyond it from the means.
  CloudMetricsConfig capped;
  capped.max_distance = 0.002;
  const CloudMetrics c = evaluate_cloud(plane_grid(d), plane_grid(), capped);
  EXPECT_DOUBLE_EQ(c.accuracy_outliers, 1.0);
}

TEST(CloudMetrics, HalfCloudIsAccurateButIncomplete) {
  PointCloud half;
  const PointCloud gt = plane_grid();
  for (const auto& p : gt.points)
    if (p.x() < 0.0745f) half.points.push_back(p);
  const CloudMetrics m = evaluate_cloud(half, gt);
  EXPECT_EQ(m.accuracy_mean, 0.0);
  EXPECT_GT(m.completeness_mean, 0.01);  // the missing half is up to 75 mm away
  EXPECT_NEAR(m.recall[0], 0.5, 0.02);
  EXPECT_DOUBLE_EQ(m.precision[0], 1.0);
  EXPECT_THROW(evaluate_cloud(gt, PointCloud()), std::invalid_argument);
}

TEST(CloudMetrics, DownsamplingKeepsTheMinimumSpacing) {
  const PointCloud d = downsample_min_spacing(plane_grid(), 0.0025);
  EXPECT_LT(d.size(), plane_grid().size() / 4);
  EXPECT_GT(d.size(), plane_grid().size() / 16);
  const auto dist = nearest_distances(d.points, plane_grid().points);
  for (double x : dist) EXPECT_EQ(x, 0.0);  // kept points are input points
}

TEST(DepthMetrics, GroundTruthAgainstItselfAndKnownErrors) {
  auto gt = torch::rand({40, 50}) * 2 + 0.5;
  gt.slice(0, 0, 5).zero_();  // no ground truth in the first 5 rows
  const DepthMetrics self = evaluate_depth(gt, gt, torch::Tensor());
  EXPECT_EQ(self.gt_pixels, 35 * 50);
  EXPECT_EQ(self.mae, 0.0);
  EXPECT_EQ(self.abs_rel, 0.0);
  EXPECT_DOUBLE_EQ(self.completeness(), 1.0);
  for (double w : self.within_rel) EXPECT_DOUBLE_EQ(w, 1.0);

  auto est = gt * 1.02;  // 2 % too far everywhere
  est.slice(0, 5, 14).zero_();  // and no estimate on 9 of the 35 valid rows
  const DepthMetrics m = evaluate_depth(est, gt, torch::Tensor());
  EXPECT_NEAR(m.abs_rel, 0.02, 1e-6);
  EXPECT_DOUBLE_EQ(m.within_rel[0], 0.0);  // 1 %
  EXPECT_DOUBLE_EQ(m.within_rel[1], 1.0);  // 3 %
  EXPECT_NEAR(m.completeness(), 26.0 / 35.0, 1e-12);
  const double expected_mae = (gt.slice(0, 14) * 0.02).mean().item<double>();
  EXPECT_NEAR(m.mae, expected_mae, 1e-6);
  EXPECT_THROW(evaluate_depth(est.slice(0, 1), gt, torch::Tensor()), std::invalid_argument);
}

// A wall at z = 2 m seen straight on by a 64x48 camera (f = 50 px) and by sources moved sideways:
// a source 0.64 m to the right sees the wall 16 px further left, so the reference's first 16
// columns lie outside it.
TEST(Covisibility, SourcesOutOfViewAndOccludersHideReferencePixels) {
  Eigen::Matrix3d K;
  K << 50, 0, 31.5, 0, 50, 23.5, 0, 0, 1;
  const auto camera_at = [&](double x) {
    Camera c;
    c.K = K;
    c.T_cam_world(0, 3) = -x;  // centre at (x, 0, 0), looking along +z
    c.width = 64;
    c.height = 48;
    return c;
  };
  const auto wall = torch::full({48, 64}, 2.0f);
  DepthView right{wall.clone(), camera_at(0.64)};
  // Something 1 m in front of the right source hides its columns 30-39: reference columns 46-55.
  right.depth.slice(1, 30, 40).fill_(1.0f);
  const DepthView left{wall.clone(), camera_at(-0.64)};

  const auto seen = covisible_by_ground_truth(wall, camera_at(0.0), {right});
  ASSERT_EQ(seen.sizes(), wall.sizes());
  const auto column_seen = [&](const torch::Tensor& mask, int u) { return mask.select(1, u).all().item<bool>(); };
  const auto column_unseen = [&](const torch::Tensor& mask, int u) { return !mask.select(1, u).any().item<bool>(); };
  for (int u : {0, 8, 14}) EXPECT_TRUE(column_unseen(seen, u)) << "column " << u << " lies outside the source";
  for (int u : {17, 30, 44}) EXPECT_TRUE(column_seen(seen, u)) << "column " << u;
  for (int u : {47, 50, 54}) EXPECT_TRUE(column_unseen(seen, u)) << "column " << u << " is hidden in the source";
  for (int u : {57, 63}) EXPECT_TRUE(column_seen(seen, u)) << "column " << u;
  const double share = seen.to(torch::kFloat64).mean().item<double>();
  EXPECT_NEAR(share, 38.0 / 64.0, 3.0 / 64.0);  // 64 columns - 16 outside - 10 hidden

  // A source on the other side sees the first columns (16 px further right); columns 46-55 stay
  // unseen: hidden in the right source, outside the left one.
  const auto either = covisible_by_ground_truth(wall, camera_at(0.0), {right, left});
  for (int u : {0, 8, 30, 60}) EXPECT_TRUE(column_seen(either, u)) << "column " << u;
  EXPECT_TRUE(column_unseen(either, 50));
  // No ground truth in the reference, no covisible pixel.
  EXPECT_FALSE(covisible_by_ground_truth(torch::zeros_like(wall), camera_at(0.0), {right}).any().item<bool>());
}

// A ground-truth depth map with a distinct value per pixel, and an estimate at a quarter of its
// size: same pose, or turned by 0.5 degrees as after `umvs refine-poses` (same image).
TEST(SampleDepthAtCamera, ATurnedEstimateIsComparedPixelForPixelOnlyWhenAllowed) {
  Camera gt_camera;
  gt_camera.K << 64, 0, 31.5, 0, 64, 23.5, 0, 0, 1;
  gt_camera.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(0.1, -0.2, 0.3);
  gt_camera.width = 64;
  gt_camera.height = 48;
  const auto gt = torch::arange(1, 64 * 48 + 1, torch::kFloat32).view({48, 64});
  Camera estimate = gt_camera;
  estimate.K.topRows<2>() *= 0.25;
  estimate.width = 16;
  estimate.height = 12;
  const auto same_pose = sample_depth_at_camera(gt, gt_camera, estimate);
  EXPECT_TRUE(same_pose.equal(gt.slice(0, 0, 48, 4).slice(1, 0, 64, 4))) << "pixel (4i, 4j)";

  const Camera turned = estimate.turned(Eigen::Vector3d(0.3, -0.4, 0.1) * M_PI / 180.0);  // 0.5 degrees
  EXPECT_THROW(sample_depth_at_camera(gt, gt_camera, turned), std::invalid_argument);
  EXPECT_THROW(sample_depth_at_camera(gt, gt_camera, turned, 0.4), std::invalid_argument);
  EXPECT_TRUE(sample_depth_at_camera(gt, gt_camera, turned, 1.0).equal(same_pose));
  Camera moved = estimate;
  moved.T_cam_world(0, 3) += 0.01;
  EXPECT_THROW(sample_depth_at_camera(gt, gt_camera, moved, 1.0), std::invalid_argument) << "a moved centre is never accepted";
}

}  // namespace
}  // namespace umvs

namespace umvs {
namespace {

TEST(Sparsification, AConfidenceThatRanksTheErrorsFollowsTheOracle) {
  // Errors 0.01 .. 1.00; a confidence that orders them exactly, one that orders them backwards,
  // and a constant one.
  const auto err = torch::arange(1, 101, torch::kFloat64) / 100;
  const auto perfect = sparsification_curve(err, 1.0 - err, 10);
  ASSERT_EQ(perfect.kept.size(), 10u);
  EXPECT_DOUBLE_EQ(perfect.kept.front(), 0.1);
  EXPECT_NEAR(perfect.abs_rel.front(), 0.055, 1e-12);  // mean of 0.01 .. 0.10
  EXPECT_NEAR(perfect.abs_rel.back(), 0.505, 1e-12);   // every pixel
  EXPECT_NEAR(perfect.ause, 0.0, 1e-12);
  const auto backwards = sparsification_curve(err, err, 10);
  EXPECT_NEAR(backwards.abs_rel.front(), 0.955, 1e-12);  // mean of 0.91 .. 1.00
  EXPECT_NEAR(backwards.oracle.front(), 0.055, 1e-12);
  EXPECT_GT(backwards.ause, 0.3);
  const auto flat = sparsification_curve(err, torch::ones_like(err), 10);
  EXPECT_GT(flat.ause, 0.1);
  EXPECT_LT(flat.ause, backwards.ause);
  EXPECT_THROW(sparsification_curve(err, torch::ones({3}), 10), std::invalid_argument);
}

TEST(DepthMapPoints, BackProjectsValidPixelsIntoTheWorld) {
  Camera cam;
  cam.K << 10, 0, 1.5, 0, 10, 1.5, 0, 0, 1;
  cam.width = 4;
  cam.height = 4;
  cam.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(0, 0, -1);  // camera at z = +1 in the world
  auto depth = torch::full({4, 4}, 2.0f);
  depth[0][0] = 0.0f;
  depth[1][1] = std::numeric_limits<float>::quiet_NaN();
  const auto all = depth_map_points(depth, cam, 1);
  EXPECT_EQ(all.size(), 14u);
  for (const auto& p : all.points) EXPECT_NEAR(p.z(), 3.0f, 1e-6);  // 2 m in front of a camera at z = 1
  EXPECT_EQ(depth_map_points(depth, cam, 2).size(), 3u);              // (0,2), (2,0), (2,2); (0,0) has none
  EXPECT_THROW(depth_map_points(torch::ones({3, 4}), cam, 1), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
