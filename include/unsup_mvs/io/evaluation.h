// Scoring folders against ground truth (what `umvs eval depth|cloud` prints): depth maps of an
// estimate folder against a scene's depth_gt/, and the reference cloud of an RGB-D set's sensor
// depth. The metrics themselves are in core/metrics.h; this is the folder walk and the report.
#pragma once

#include <torch/types.h>

#include <iosfwd>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

struct DepthFolderEvalOptions {
  std::string est_subdir;             // subfolder of the estimate with the maps; "" = depth_est, depth_gt or depth
  double min_confidence = 0.0;        // > 0: ignore estimates whose confidence map is below it
  DepthMetricsConfig metrics;
  std::vector<int> views;             // empty = every XXXXXXXX.pfm of the estimate
  int covisibility_sources = 0;       // > 0: split by whether one of the first N neighbours (pair.txt) sees the pixel
  double max_turn_deg = 0.0;          // accept estimate cameras turned this much from the ground truth's
  bool sparsification = false;        // also judge the confidence maps
  std::vector<double> confidence_levels{0.5, 0.8};  // with sparsification: floors reported
  double confident_within = 0.1;      // with sparsification: relative error counted as right
  void validate() const;              // std::invalid_argument naming the bad option
};

struct DepthFolderEvaluation {
  std::string est_dir;                // the folder of depth maps scored
  std::vector<int> views;             // in order
  std::vector<DepthMetrics> per_view;
  DepthMetrics overall;
  // With covisibility_sources > 0 (else empty): the pixels a neighbour sees, and the others.
  std::vector<DepthMetrics> per_view_seen, per_view_unseen;
  DepthMetrics seen, unseen;
  // With sparsification (else empty).
  Sparsification curve;
  std::vector<ConfidentPixels> confident;

  bool split() const { return !per_view_seen.empty(); }
};

// Share of the ground-truth pixels that lie in the `seen` part.
double seen_share(const DepthMetrics& seen, const DepthMetrics& unseen);

// Depth maps of `est_root` (umvs infer's folder, depth_gt/ or depth/, or the .pfm files directly)
// against `gt_root`'s depth_gt/ (a `umvs synth` or `umvs import` folder). An estimate at another
// resolution is compared at its own pixels through the two cameras (same pose, or turned by up to
// max_turn_deg). Throws naming the file or option at fault.
DepthFolderEvaluation evaluate_depth_folder(const std::string& est_root, const std::string& gt_root,
                                            const DepthFolderEvalOptions& options);

// The points of an RGB-D folder's sensor depth (depth_gt/, cams/), every `stride`-th pixel of the
// given views (empty = all), thinned to `spacing` (0 = not thinned): the reference for a fused cloud.
PointCloud sensor_depth_cloud(const std::string& folder, std::vector<int> views, int stride, double spacing);

// Reports. JSON keeps the order written; NaN (metrics without pixels) prints as null.
nlohmann::ordered_json to_json(const DepthFolderEvaluation& eval, const DepthFolderEvalOptions& options);
void print_table(std::ostream& out, const DepthFolderEvaluation& eval, const DepthFolderEvalOptions& options,
                 const std::string& gt_root);
nlohmann::ordered_json to_json(const CloudMetrics& metrics);
void print_table(std::ostream& out, const CloudMetrics& metrics, const std::string& est_name, const std::string& gt_name,
                 bool downsampled);

}  // namespace umvs
