// `umvs refine-poses`: an MVSNet-format folder whose cameras are turned, label-free, so that
// its views agree. For each reference and its best neighbours in pair.txt the depth estimator
// measures the turn of the neighbour that warps it best onto the reference
// (DepthEstimator::best_source_turn); the turns it keeps are made consistent over all views
// (consistent_view_turns), and the new folder gets the corrected cameras. Only the orientations
// change, about each camera's centre; images, pair.txt and depth ranges are copied. depth_gt/ is
// neither read nor copied: evaluate against the original folder.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/pose_refinement.h"

namespace umvs {

struct PoseRefinementConfig {
  std::string data_dir;      // MVSNet-format folder (images/, cams/, pair.txt)
  std::string out_dir;       // new folder; refused when it exists and is not empty
  std::vector<int> refs;     // reference views to measure from (empty = every view in pair.txt)
  int sources = 2;           // neighbours per reference, best first in pair.txt
  double search_deg = 2.0;   // largest turn about each axis, per round
  int rounds = 2;            // measure and solve again from the corrected cameras
};

struct MeasuredPair {
  int round = 1;
  int reference = 0, source = 0;
  SourceTurn turn;
  // Whether the pair was a measurement: its turn when kept, zero when the search found no clearly
  // better turn (the pair agrees as posed); not when the search and the full-size check disagree.
  bool used = false;
  double residual_deg = 0.0;  // used pairs: how far the round's consistent turns are from the measurement
};

struct PoseRefinementResult {
  std::vector<MeasuredPair> pairs;  // in the order measured, round after round
  // Per view, the whole turn written (degrees about the camera's x, y, z, as Camera::turned).
  std::map<int, Eigen::Vector3d> view_degrees;
};

// Measures, solves and writes out_dir (cams/ with the turned cameras, images/ and pair.txt copied,
// pose_refinement.txt with the measurements and the turns). `on_pair` is called after each
// measurement (done, total). Throws std::invalid_argument for bad options or an output folder that
// is the input or holds files, std::runtime_error for unreadable input; nothing is written before
// all measurements succeed.
PoseRefinementResult refine_folder_poses(const PoseRefinementConfig& config, DepthEstimator& estimator,
                                         const std::function<void(int done, int total, const MeasuredPair&)>& on_pair = {});

}  // namespace umvs
