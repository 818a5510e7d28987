#include "unsup_mvs/core/view_selection.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {

double view_angle_score(double theta_deg, const ViewScoreConfig& c) {
  const double d = theta_deg - c.theta0_deg;
  const double sigma = theta_deg <= c.theta0_deg ? c.sigma1_deg : c.sigma2_deg;
  return std::exp(-d * d / (2.0 * sigma * sigma));
}

double view_selection_score(const std::vector<Eigen::Vector3d>& points, const Camera& ref,
                            const Camera& src, const ViewScoreConfig& config) {
  const Eigen::Vector3d ca = ref.center(), cb = src.center();
  double score = 0.0;
  Eigen::Vector2d uv;
  for (const auto& p : points) {
    if (!ref.project(p, &uv) || !ref.in_image(uv)) continue;
    if (!src.project(p, &uv) || !src.in_image(uv)) continue;
    const Eigen::Vector3d a = (ca - p).normalized(), b = (cb - p).normalized();
    const double theta = std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / M_PI;
    score += view_angle_score(theta, config);
  }
  return score;
}

std::vector<Eigen::Vector3d> sample_frustum_points(const Camera& ref, double depth, int grid) {
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(static_cast<size_t>(grid) * grid);
  for (int j = 0; j < grid; ++j) {
    for (int i = 0; i < grid; ++i) {
      const double u = (i + 0.5) / grid * ref.width - 0.5;
      const double v = (j + 0.5) / grid * ref.height - 0.5;
      pts.push_back(ref.backproject(u, v, depth));
    }
  }
  return pts;
}

double view_selection_depth(double near, double far) {
  if (!(near > 0.0) || !(far >= near) || !std::isfinite(far)) {
    throw std::invalid_argument("view_selection_depth: need 0 < near <= far, got near " + std::to_string(near) +
                                ", far " + std::to_string(far));
  }
  return std::sqrt(near * far);
}

std::vector<ScoredView> rank_source_views(const std::vector<Eigen::Vector3d>& points,
                                          const Camera& ref, const std::vector<Camera>& candidates,
                                          const ViewScoreConfig& config) {
  std::vector<double> scores(candidates.size(), 0.0);
  at::parallel_for(0, static_cast<int64_t>(candidates.size()), 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) scores[i] = view_selection_score(points, ref, candidates[i], config);
  });
  std::vector<ScoredView> ranked;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (scores[i] > 0.0) ranked.push_back({static_cast<int>(i), scores[i]});
  }
  std::stable_sort(ranked.begin(), ranked.end(),
                   [](const ScoredView& a, const ScoredView& b) { return a.score > b.score; });
  return ranked;
}

}  // namespace umvs
