// Depth and confidence maps for the views of an MVSNet-format folder (what `umvs infer` does):
// each reference with its best neighbours from pair.txt through a DepthEstimator, written as an
// InferenceFolder (depth_est/, confidence/, cams/, images/, pair.txt) that `umvs fuse` and
// `umvs eval` read.
#pragma once

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "unsup_mvs/core/depth_estimator.h"

namespace umvs {

struct FolderInferenceOptions {
  std::string depth_sampling, feature_warp;  // "" = the checkpoint's (depth | inverse_depth; exact | mvsnet_pytorch)
  int views = 3;                   // per depth map: the reference and views-1 neighbours
  std::vector<int> refs;           // empty = every reference view of pair.txt
  double depth_min = 0.0;          // > 0 overrides the cam files' near end
  double depth_max = 0.0;          // > 0 overrides the cam files' far end
  int num_depth = 0;               // 0 = 128 at 640 wide, scaled with the width (or the weights' own)
  DepthEstimatorConfig estimator;  // num_depth is chosen by the run
  // Throws std::invalid_argument naming the option (as `umvs infer` spells it).
  void validate() const;
};

struct FolderInferenceResult {
  int done = 0, skipped = 0;      // skipped: fewer neighbours in pair.txt than views-1
  double network_seconds = 0.0;   // summed over the maps
  int num_depth = 0;
  std::string planes_why;         // how the plane count was chosen
};

// Called after each reference view with the views finished so far (written or skipped), how many
// there are, and a one-line summary of the last one.
using FolderInferenceProgress = std::function<void(int finished, int total, const std::string& line)>;

// Runs the model of `checkpoint` (ours or MVSNet_pytorch weights) over `data_dir`'s views into
// `out_dir` (created). What a user should read (the model, the plane count, skipped views, the
// depth range in use, rotation-search results) goes to `log`. Refuses before loading the model
// when an option or a reference view is wrong, and before writing anything when the first input
// would not fit in memory.
FolderInferenceResult infer_folder(const std::string& data_dir, const std::string& checkpoint, const torch::Device& device,
                                   const std::string& out_dir, const FolderInferenceOptions& options, std::ostream& log,
                                   const FolderInferenceProgress& progress = {});

}  // namespace umvs
