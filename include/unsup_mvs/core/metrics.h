// Evaluation metrics, implemented once for `umvs eval`, validation during training and tests.
//
// Depth maps: errors over the pixels where both the ground truth (> 0, finite) and the estimate
// are valid; completeness = that count / the number of valid ground-truth pixels. Per-view results
// combine into an overall one weighted by pixel counts (so the overall is over all pixels).
//
// Point clouds: DTU-style accuracy (estimate -> ground truth nearest-neighbour distances) and
// completeness (ground truth -> estimate), mean and median, with distances above an outlier cap
// left out (DTU's 20 mm); overall = the mean of the two means. Tanks-and-Temples precision
// (share of estimate points within a threshold of the ground truth), recall (the converse) and
// F-score = 2PR/(P+R). Nearest neighbours by a KD-tree (nanoflann). Shares are in [0,1].
// LibTorch + Eigen (+ header-only nanoflann in the .cpp).
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

// ---------------------------------------------------------------------------------------------
// Depth maps

struct DepthMetricsConfig {
  std::vector<double> rel_thresholds = {0.01, 0.03};    // |e| / gt
  std::vector<double> abs_thresholds = {0.001, 0.003};  // |e| in scene units (the paper's 1 and 3 mm on DTU in metres)
};

struct DepthMetrics {
  int64_t gt_pixels = 0;         // valid ground-truth pixels
  int64_t evaluated_pixels = 0;  // ... that also have a valid estimate
  double mae = 0.0;              // mean |est - gt| (scene units), NaN when nothing is evaluated
  double abs_rel = 0.0;          // mean |est - gt| / gt
  double rmse = 0.0;
  std::vector<double> within_rel;  // share of evaluated pixels under each rel threshold
  std::vector<double> within_abs;  // share of evaluated pixels under each abs threshold
  double completeness() const { return gt_pixels > 0 ? static_cast<double>(evaluated_pixels) / gt_pixels : 0.0; }
};

// est, gt: [H,W] depth (same size), est_valid: [H,W] bool, or undefined = est > 0 and finite.
// Throws std::invalid_argument naming the problem for mismatched shapes.
DepthMetrics evaluate_depth(const torch::Tensor& est, const torch::Tensor& gt, const torch::Tensor& est_valid,
                            const DepthMetricsConfig& config = {});
// Pixel-weighted combination of per-view metrics (all computed with the same config).
DepthMetrics combine_depth_metrics(const std::vector<DepthMetrics>& parts);

// The ground-truth depth at the pixels of a depth map with another camera of the same pose
// (e.g. MVSNet's 1/4-resolution output): est pixel (u,v) looks up the ground-truth pixel nearest to
// K_gt K_est^-1 (u,v,1) -- for `umvs infer` output without resizing that is exactly (4u, 4v).
// gt: [H,W] -> [h,w] (0 where the pixel falls outside the ground truth). Throws
// std::invalid_argument when the two cameras' poses differ (rotation or centre).
// `max_turn_deg` > 0 accepts an estimate whose camera is turned about the same centre by up to that
// angle: one whose pose `umvs refine-poses` corrected. Its image is the same, so pixels then map by
// K_gt K_est^-1 alone.
torch::Tensor sample_depth_at_camera(const torch::Tensor& gt, const Camera& gt_camera, const Camera& est_camera,
                                     double max_turn_deg = 0.0);

// Which pixels of a reference view some source view also sees, decided on ground truth alone:
// the pixel's ground-truth point passes fusion's round trip (check_consistency at 1 px and
// max_relative_depth) against at least one source's ground truth, so it lies inside that source
// and is not hidden there. Splits depth errors into those where multi-view stereo had something
// to match and those where it could only guess. 3 %, not fusion's 1 %: the ground truth of two
// far-apart views of a slanted wall differs by 1-3 % after the round trip (the living room's
// frames 4 and 1), and an occluder is much farther off than that.
//   ref_gt [h,w] (0 = no ground truth) seen by ref_camera; sources: [Hs,Ws] ground truth with its
//   camera.  -> [h,w] bool
struct DepthView {
  torch::Tensor depth;
  Camera camera;
};
torch::Tensor covisible_by_ground_truth(const torch::Tensor& ref_gt, const Camera& ref_camera,
                                        const std::vector<DepthView>& sources, double max_relative_depth = 0.03);

// Whether confidence ranks errors (Ilg et al. 2018, "uncertainty estimates and multi-hypotheses
// networks for optical flow"): keep the most confident share of the evaluated pixels and take
// their abs rel; the oracle keeps the pixels of least error instead. A confidence that ranks
// well follows the oracle; AUSE is the mean gap between the two over the shares (0 = perfect).
//   rel_error, confidence: [N] over the evaluated pixels (any shape; flattened).
struct Sparsification {
  std::vector<double> kept;     // shares of the pixels kept: 1/steps .. 1
  std::vector<double> abs_rel;  // abs rel of the most confident `kept` share
  std::vector<double> oracle;   // abs rel of the `kept` share of least error
  double ause = 0.0;            // mean of abs_rel - oracle
};
Sparsification sparsification_curve(const torch::Tensor& rel_error, const torch::Tensor& confidence, int steps = 10);

// What a planner reading the map at a confidence floor gets: the share of the depth map's pixels
// at or above it, and of those with ground truth, the abs rel and the share within `within_rel`.
struct ConfidentPixels {
  double level = 0.0;
  int64_t pixels = 0;          // pixels of the depth maps
  int64_t confident = 0;       // ... with confidence >= level and an estimate
  int64_t scored = 0;          // ... of which have ground truth
  double abs_rel = 0.0;        // over `scored` (NaN when none)
  double within = 0.0;         // share of `scored` within within_rel
  double image_share() const { return pixels > 0 ? static_cast<double>(confident) / pixels : 0.0; }
};

// ---------------------------------------------------------------------------------------------
// Point clouds

// The points of a depth map ([H,W] metres, <= 0 or non-finite = none) seen by `camera` (of the
// same size), every `stride`-th pixel each way, in world coordinates: the reference cloud of a
// sensor's depth for scoring a fused cloud.
PointCloud depth_map_points(const torch::Tensor& depth, const Camera& camera, int stride = 1);

struct CloudMetricsConfig {
  // Distances above this are outliers, left out of the means and medians (DTU: 20 mm); 0 = keep all.
  double max_distance = 0.0;
  // Precision/recall thresholds (scene units). Tanks and Temples uses one per scene.
  std::vector<double> thresholds = {0.002, 0.005, 0.01};
  // Reduce both clouds to this minimum spacing first (DTU: 0.2 mm); 0 = use them as they are.
  double downsample_spacing = 0.0;
};

struct CloudMetrics {
  size_t est_points = 0, gt_points = 0;  // after downsampling
  double accuracy_mean = 0.0, accuracy_median = 0.0;          // est -> gt
  double completeness_mean = 0.0, completeness_median = 0.0;  // gt -> est
  double overall = 0.0;                                       // (accuracy_mean + completeness_mean) / 2
  double accuracy_outliers = 0.0, completeness_outliers = 0.0;  // share of distances above max_distance
  std::vector<double> thresholds, precision, recall, fscore;   // one per threshold, shares in [0,1]
};

// Throws std::invalid_argument when the ground truth is empty or the config is invalid. An empty
// estimate gives NaN distances and zero precision, recall and F-score.
CloudMetrics evaluate_cloud(const PointCloud& est, const PointCloud& gt, const CloudMetricsConfig& config = {});

// Greedy minimum-spacing subsample in input order: a point is kept when no kept point lies within
// `spacing` of it (DTU's downsampling). Colours and attributes follow the kept points.
PointCloud downsample_min_spacing(const PointCloud& cloud, double spacing);

// Distance from every query point to its nearest neighbour in `reference` (KD-tree).
std::vector<double> nearest_distances(const std::vector<Eigen::Vector3f>& queries,
                                      const std::vector<Eigen::Vector3f>& reference);

}  // namespace umvs
