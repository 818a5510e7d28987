// MVSNet's view-selection score (Yao et al. 2018, sec. 4.1): for a reference and a source view,
// sum over the surface points both see of a piecewise Gaussian in the triangulation angle theta:
//   G(theta) = exp(-(theta - theta0)^2 / (2 sigma1^2))  for theta <= theta0
//              exp(-(theta - theta0)^2 / (2 sigma2^2))  otherwise
// with theta0 = 5 deg, sigma1 = 1, sigma2 = 10. Used by `umvs synth` (pair.txt), the keyframe
// selector and the training-tuple builder, so all three rank neighbours the same way.
#pragma once

#include <vector>

#include "unsup_mvs/core/camera.h"

namespace umvs {

struct ViewScoreConfig {
  double theta0_deg = 5.0;
  double sigma1_deg = 1.0;
  double sigma2_deg = 10.0;
};

// G(theta) for one triangulation angle in degrees.
double view_angle_score(double theta_deg, const ViewScoreConfig& config = {});

// Sum of G over the points that project inside both images with positive depth.
double view_selection_score(const std::vector<Eigen::Vector3d>& points_world, const Camera& ref,
                            const Camera& src, const ViewScoreConfig& config = {});

// A grid of grid x grid points on the reference image back-projected at `depth`: stand-in
// surface points when no geometry is known yet (keyframes: view_selection_depth of the range).
std::vector<Eigen::Vector3d> sample_frustum_points(const Camera& ref, double depth, int grid = 16);

// The depth at which keyframes are scored when only the depth range [near, far] is known: its
// geometric mean, the middle of the range on a log scale. The arithmetic middle lies far behind
// most of a wide range (a street seen at 2.7-45 m: 24 m, where adjacent keyframes triangulate
// under the score's 5 degrees), so it picked far-apart neighbours.
// Throws std::invalid_argument unless 0 < near <= far (both finite).
double view_selection_depth(double near, double far);

struct ScoredView {
  int index = 0;
  double score = 0.0;
};
// Candidate indices sorted by decreasing score (ties by index); views scoring 0 are dropped.
std::vector<ScoredView> rank_source_views(const std::vector<Eigen::Vector3d>& points_world,
                                          const Camera& ref, const std::vector<Camera>& candidates,
                                          const ViewScoreConfig& config = {});

}  // namespace umvs
