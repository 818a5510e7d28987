// Online counterpart of `umvs refine-poses` for a stream of keyframe sets (the inference nodelet):
// each (reference, source) pair of keyframes is measured once, on the poses as given
// (DepthEstimator::best_source_turn), and every set is served with the cameras turned by the
// per-keyframe turns that agree best with all pairs measured so far (consistent_view_turns).
// Depth maps, and the poses sent on with them to fusion, then agree across keyframes.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <optional>
#include <utility>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/pose_refinement.h"

namespace umvs {

// How a pair's rotation search counts as a measurement of the two views' relative turn: a kept turn
// is measured as found; a search that found no clearly better turn says the pair agrees as posed
// (zero); when the half-size search and the full-size check disagree the pair says nothing (none).
std::optional<Eigen::Vector3d> measured_pair_turn(const SourceTurn& turn);

struct KeyframePoseRefinerConfig {
  double search_deg = 2.0;    // largest turn about each axis a pair measurement looks for (> 0)
  size_t max_keyframes = 100;  // keyframes remembered; beyond this the least recently used is forgotten
  void validate() const;       // throws std::invalid_argument naming the field
};

class KeyframePoseRefiner {
 public:
  explicit KeyframePoseRefiner(KeyframePoseRefinerConfig config = {});

  // views[0] is the reference; ids[i] names the keyframe of views[i]. Measures the pairs
  // (ids[0], ids[s]) not measured yet, solves over every pair measured, and returns the views with
  // their cameras turned about their centres. A keyframe whose pose as given differs from the one
  // it was measured with (a SLAM back end moved it) forgets its pairs first. Throws
  // std::invalid_argument for ids that do not match the views or repeat, more views than
  // max_keyframes, and as
  // DepthEstimator::best_source_turn does for the views; it then remembers nothing of this set.
  std::vector<ViewInput> correct(DepthEstimator& estimator, const std::vector<int64_t>& ids, std::vector<ViewInput> views,
                                 double depth_min, double depth_max);

  // The turn now applied to a keyframe (degrees about its own x, y, z); zero for an unknown one.
  Eigen::Vector3d turn_degrees(int64_t id) const;
  size_t keyframes() const { return keyframes_.size(); }
  size_t measured_pairs() const { return pairs_.size(); }
  // Measurements made by the last correct() (0 when all its pairs were known).
  int last_new_measurements() const { return last_new_measurements_; }

 private:
  struct Keyframe {
    Camera given;  // the camera as given when its pairs were measured
    uint64_t last_used = 0;
    Eigen::Vector3d turn_degrees = Eigen::Vector3d::Zero();
  };
  void forget(int64_t id);
  void solve();

  KeyframePoseRefinerConfig config_;
  std::map<int64_t, Keyframe> keyframes_;
  // (reference, source) -> the measured relative turn, or none when the pair said nothing.
  std::map<std::pair<int64_t, int64_t>, std::optional<Eigen::Vector3d>> pairs_;
  uint64_t clock_ = 0;
  int last_new_measurements_ = 0;
};

}  // namespace umvs
