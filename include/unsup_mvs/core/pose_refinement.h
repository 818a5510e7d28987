// One set of camera orientations from many pairwise turns. DepthEstimator::best_source_turn
// measures, for a reference and a source, the small turn of the source that makes its warp onto the
// reference best; this finds the turn of every view that agrees best with all those measurements,
// so that inference, fusion and training can use corrected poses without searching per map.
#pragma once

#include <Eigen/Core>
#include <map>
#include <vector>

#include "unsup_mvs/core/camera.h"

namespace umvs {

// A measured turn of the `source` camera, with the `reference` camera held fixed: degrees about
// the source's own x, y, z (Camera::turned takes it in radians).
struct PairTurn {
  int reference = 0;
  int source = 0;
  Eigen::Vector3d degrees = Eigen::Vector3d::Zero();
};

struct ConsistentTurns {
  // Per view: the turn (degrees about its own x, y, z) to apply with Camera::turned. Every view of
  // `cameras` is here; one that no measurement names keeps its pose (zero turn).
  std::map<int, Eigen::Vector3d> view_degrees;
  // Per measurement, in its order: the angle (degrees) between the relative turn the solution gives
  // that pair and the measured one. Large values mean measurements that disagree with the others.
  std::vector<double> residual_degrees;
};

// The per-view turns whose relative turns match the measurements best (least squares on the small
// angles, in the world frame). A pair only fixes the two views' relative orientation, so turning
// every view alike explains the measurements as well; of all such solutions this is the one whose
// turns are smallest in total. Throws std::invalid_argument for a measurement naming a view that
// is not in `cameras`, a pair of a view with itself, or a non-finite angle.
ConsistentTurns consistent_view_turns(const std::map<int, Camera>& cameras, const std::vector<PairTurn>& measurements);

}  // namespace umvs
