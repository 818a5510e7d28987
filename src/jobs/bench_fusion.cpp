// The fusion benchmark of unsup_mvs/jobs/bench.h: a reference and `sources` views on an arc
// (+-15 degrees) 2 m from a slanted plane that fills every image, so every pixel is an estimate
// (the worst case). Each run fuses every view against all the others.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/jobs/bench.h"

namespace umvs {

namespace {

// View i of `sources` + 1 on the arc, with the plane's exact depth.
FusionView plane_view(int i, int sources, int W, int H) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.3, 1.0).normalized();  // plane n.X = 0 through the origin
  const double a = (2.0 * i / sources - 1.0) * 15.0 * M_PI / 180.0;
  const Eigen::Vector3d eye(2.0 * std::sin(a), 0.1 * std::cos(3 * a), -2.0 * std::cos(a));
  const Eigen::Vector3d f = (-eye).normalized();
  const Eigen::Vector3d r = Eigen::Vector3d::UnitY().cross(f).normalized();
  Eigen::Matrix3d R;
  R.row(0) = r;
  R.row(1) = f.cross(r);
  R.row(2) = f;
  FusionView v;
  v.id = i;
  v.camera.width = W;
  v.camera.height = H;
  v.camera.K << 0.9 * W, 0, (W - 1) / 2.0, 0, 0.9 * W, (H - 1) / 2.0, 0, 0, 1;
  v.camera.T_cam_world.topLeftCorner<3, 3>() = R;
  v.camera.T_cam_world.topRightCorner<3, 1>() = -R * eye;
  // z-depth along each pixel ray d (camera z = 1): eye + s d on the plane -> s = -n.eye / n.d
  const Eigen::Vector3d m = (R.transpose() * v.camera.K.inverse()).transpose() * n;  // n.d = m.(x, y, 1)
  auto xs = torch::arange(W, torch::kFloat64).view({1, W}), ys = torch::arange(H, torch::kFloat64).view({H, 1});
  v.depth = (-n.dot(eye) / (m.x() * xs + m.y() * ys + m.z())).to(torch::kFloat32);
  v.confidence = torch::ones_like(v.depth);
  v.color = torch::full({H, W, 3}, 128, torch::kUInt8);
  return v;
}

}  // namespace

FusionBenchResult bench_fusion(const FusionBenchOptions& options, const torch::Device& device) {
  const int W = options.width, H = options.height, S = options.sources;
  if (S < 1) throw std::invalid_argument("--sources must be >= 1");
  if (options.runs.runs < 1) throw std::invalid_argument("--runs must be >= 1");
  std::vector<FusionView> views;
  for (int i = 0; i <= S; ++i) views.push_back(plane_view(i, S, W, H));
  FusionConfig cfg;
  cfg.max_source_views = S;
  DepthFusion fusion(cfg, device);
  std::vector<double> per_view, rates, ranking, consistency, making_points;
  FusionBenchResult result;
  for (int r = 0; r < options.runs.warmup + options.runs.runs; ++r) {
    std::vector<FusionViewStats> stats;
    const auto t0 = std::chrono::steady_clock::now();
    result.points = fusion.fuse(views, {}, &stats).size();
    const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r < options.runs.warmup) continue;
    per_view.push_back(total / views.size());
    rates.push_back(result.points / total);
    for (const auto& st : stats) {
      ranking.push_back(st.ranking_seconds);
      consistency.push_back(st.consistency_seconds);
      making_points.push_back(st.points_seconds);
    }
  }
  result.width = W;
  result.height = H;
  result.sources = S;
  result.views = static_cast<int>(views.size());
  result.per_view = summarize(per_view);
  // Per reference view, median over views and runs; the rest of a view's time is preparing the
  // views (validity masks) once per fusion.
  result.ranking_s = summarize(ranking).median;
  result.consistency_s = summarize(consistency).median;
  result.points_s = summarize(making_points).median;
  std::sort(rates.begin(), rates.end());
  result.points_per_s = rates[rates.size() / 2];
  result.peak_rss_mib = peak_rss_mib();
  return result;
}

}  // namespace umvs
