#include "unsup_mvs/core/metrics.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <nanoflann.hpp>
#include <stdexcept>
#include <unordered_map>

#include "unsup_mvs/core/fusion.h"

namespace umvs {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void check_thresholds(const std::vector<double>& t, const char* what) {
  for (double v : t) {
    if (!(v > 0.0) || !std::isfinite(v)) throw std::invalid_argument(std::string(what) + " must be positive and finite");
  }
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// Depth maps

DepthMetrics evaluate_depth(const torch::Tensor& est_in, const torch::Tensor& gt_in, const torch::Tensor& est_valid_in,
                            const DepthMetricsConfig& config) {
  check_thresholds(config.rel_thresholds, "relative depth thresholds");
  check_thresholds(config.abs_thresholds, "absolute depth thresholds");
  if (est_in.dim() != 2 || gt_in.dim() != 2 || est_in.sizes() != gt_in.sizes()) {
    throw std::invalid_argument("evaluate_depth: estimate " + std::to_string(est_in.dim() == 2 ? est_in.size(1) : -1) +
                                "x" + std::to_string(est_in.dim() == 2 ? est_in.size(0) : -1) +
                                " and ground truth must both be [H,W] of the same size (ground truth " +
                                std::to_string(gt_in.dim() == 2 ? gt_in.size(1) : -1) + "x" +
                                std::to_string(gt_in.dim() == 2 ? gt_in.size(0) : -1) + ")");
  }
  const auto est = est_in.detach().to(torch::kCPU, torch::kFloat64);
  const auto gt = gt_in.detach().to(torch::kCPU, torch::kFloat64);
  auto est_valid = torch::isfinite(est) & (est > 0);
  if (est_valid_in.defined()) {
    if (est_valid_in.sizes() != est_in.sizes()) throw std::invalid_argument("evaluate_depth: validity mask has the wrong size");
    est_valid = est_valid & est_valid_in.to(torch::kCPU).to(torch::kBool);
  }
  const auto gt_valid = torch::isfinite(gt) & (gt > 0);
  const auto both = gt_valid & est_valid;
  DepthMetrics m;
  m.gt_pixels = gt_valid.sum().item<int64_t>();
  m.evaluated_pixels = both.sum().item<int64_t>();
  if (m.evaluated_pixels == 0) {
    m.mae = m.abs_rel = m.rmse = kNaN;
    m.within_rel.assign(config.rel_thresholds.size(), 0.0);
    m.within_abs.assign(config.abs_thresholds.size(), 0.0);
    return m;
  }
  const auto e = est.masked_select(both), g = gt.masked_select(both);
  const auto err = (e - g).abs();
  const auto rel = err / g;
  m.mae = err.mean().item<double>();
  m.abs_rel = rel.mean().item<double>();
  m.rmse = std::sqrt(err.square().mean().item<double>());
  for (double t : config.rel_thresholds) m.within_rel.push_back((rel <= t).to(torch::kFloat64).mean().item<double>());
  for (double t : config.abs_thresholds) m.within_abs.push_back((err <= t).to(torch::kFloat64).mean().item<double>());
  return m;
}

DepthMetrics combine_depth_metrics(const std::vector<DepthMetrics>& parts) {
  DepthMetrics out;
  double mae = 0, rel = 0, sq = 0;
  for (const auto& p : parts) {
    out.gt_pixels += p.gt_pixels;
    out.evaluated_pixels += p.evaluated_pixels;
    if (out.within_rel.empty()) out.within_rel.assign(p.within_rel.size(), 0.0);
    if (out.within_abs.empty()) out.within_abs.assign(p.within_abs.size(), 0.0);
    if (p.within_rel.size() != out.within_rel.size() || p.within_abs.size() != out.within_abs.size()) {
      throw std::invalid_argument("combine_depth_metrics: parts were computed with different thresholds");
    }
    if (p.evaluated_pixels == 0) continue;
    const double w = static_cast<double>(p.evaluated_pixels);
    mae += w * p.mae;
    rel += w * p.abs_rel;
    sq += w * p.rmse * p.rmse;
    for (size_t i = 0; i < p.within_rel.size(); ++i) out.within_rel[i] += w * p.within_rel[i];
    for (size_t i = 0; i < p.within_abs.size(); ++i) out.within_abs[i] += w * p.within_abs[i];
  }
  if (out.evaluated_pixels == 0) {
    out.mae = out.abs_rel = out.rmse = kNaN;
    return out;
  }
  const double n = static_cast<double>(out.evaluated_pixels);
  out.mae = mae / n;
  out.abs_rel = rel / n;
  out.rmse = std::sqrt(sq / n);
  for (auto& v : out.within_rel) v /= n;
  for (auto& v : out.within_abs) v /= n;
  return out;
}

torch::Tensor sample_depth_at_camera(const torch::Tensor& gt_in, const Camera& gt_cam, const Camera& est_cam,
                                     double max_turn_deg) {
  if (gt_in.dim() != 2) throw std::invalid_argument("sample_depth_at_camera: ground truth must be [H,W]");
  const double rot = rotation_angle(gt_cam.R(), est_cam.R());
  const double max_rot = std::max(1e-5, max_turn_deg * M_PI / 180.0);
  const double scale = std::max(1.0, gt_cam.center().norm());
  if (rot > max_rot || (gt_cam.center() - est_cam.center()).norm() > 1e-6 * scale) {
    throw std::invalid_argument("the estimate's camera and the ground truth's camera have different poses (rotation " +
                                std::to_string(rot * 180.0 / M_PI) + " deg, centres " +
                                std::to_string((gt_cam.center() - est_cam.center()).norm()) + " apart)");
  }
  const auto gt = gt_in.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  const int H = static_cast<int>(gt.size(0)), W = static_cast<int>(gt.size(1));
  const int h = est_cam.height, w = est_cam.width;
  if (h <= 0 || w <= 0) throw std::invalid_argument("sample_depth_at_camera: the estimate's camera has no image size");
  // Same pose: pixels map by the homography K_gt R_gt R_est^T K_est^-1 (R equal up to 1e-5). A
  // turned estimate (a refined pose) has the same image, so its pixels map by K_gt K_est^-1.
  const Eigen::Matrix3d rotation =
      rot > 1e-5 ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(gt_cam.R() * est_cam.R().transpose());
  const Eigen::Matrix3d Hm = gt_cam.K * rotation * est_cam.K.inverse();
  auto out = torch::zeros({h, w}, torch::kFloat32);
  const auto g = gt.accessor<float, 2>();
  auto o = out.accessor<float, 2>();
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3d p = Hm * Eigen::Vector3d(u, v, 1.0);
      // Nearest pixel; +1e-9 so that exact half-pixels round the same way on every platform.
      const int x = static_cast<int>(std::floor(p.x() / p.z() + 0.5 + 1e-9));
      const int y = static_cast<int>(std::floor(p.y() / p.z() + 0.5 + 1e-9));
      if (x >= 0 && y >= 0 && x < W && y < H) o[v][u] = g[y][x];
    }
  }
  return out;
}

torch::Tensor covisible_by_ground_truth(const torch::Tensor& ref_gt_in, const Camera& ref_camera,
                                        const std::vector<DepthView>& sources, double max_relative_depth) {
  if (ref_gt_in.dim() != 2) throw std::invalid_argument("covisible_by_ground_truth: ground truth must be [H,W]");
  const auto ref_gt = ref_gt_in.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  const auto has_depth = [](const torch::Tensor& d) { return torch::isfinite(d) & (d > 0); };
  const auto ref_valid = has_depth(ref_gt);
  FusionConfig round_trip;
  round_trip.min_confidence = 0.0;
  round_trip.max_relative_depth = max_relative_depth;
  round_trip.validate();
  auto seen = torch::zeros_like(ref_valid);
  for (const auto& src : sources) {
    if (src.depth.dim() != 2) throw std::invalid_argument("covisible_by_ground_truth: source ground truth must be [H,W]");
    const auto src_gt = src.depth.detach().to(torch::kCPU, torch::kFloat32).contiguous();
    seen |= check_consistency(ref_gt, ref_valid, ref_camera, src_gt, has_depth(src_gt), src.camera, round_trip).agree;
  }
  return seen & ref_valid;
}

// ---------------------------------------------------------------------------------------------
// Point clouds

namespace {

struct PointsAdaptor {
  const std::vector<Eigen::Vector3f>& pts;
  size_t kdtree_get_point_count() const { return pts.size(); }
  float kdtree_get_pt(size_t i, size_t d) const { return pts[i][static_cast<int>(d)]; }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointsAdaptor>, PointsAdaptor, 3>;

double median_of(std::vector<double> v) {
  if (v.empty()) return kNaN;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  const double hi = v[mid];
  if (v.size() % 2) return hi;
  return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + mid));
}

struct DistanceSummary {
  double mean = kNaN, median = kNaN, outliers = 0.0;
};
DistanceSummary summarise(const std::vector<double>& d, double cap) {
  DistanceSummary s;
  if (d.empty()) return s;
  std::vector<double> kept;
  kept.reserve(d.size());
  for (double v : d)
    if (cap <= 0.0 || v <= cap) kept.push_back(v);
  s.outliers = 1.0 - static_cast<double>(kept.size()) / d.size();
  if (kept.empty()) return s;
  double sum = 0;
  for (double v : kept) sum += v;
  s.mean = sum / kept.size();
  s.median = median_of(std::move(kept));
  return s;
}

double share_within(const std::vector<double>& d, double t) {
  if (d.empty()) return 0.0;
  size_t n = 0;
  for (double v : d) n += v <= t;
  return static_cast<double>(n) / d.size();
}

}  // namespace

std::vector<double> nearest_distances(const std::vector<Eigen::Vector3f>& queries,
                                      const std::vector<Eigen::Vector3f>& reference) {
  std::vector<double> out(queries.size(), std::numeric_limits<double>::infinity());
  if (reference.empty() || queries.empty()) return out;
  PointsAdaptor adaptor{reference};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
  at::parallel_for(0, static_cast<int64_t>(queries.size()), 1024, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      uint32_t index = 0;
      float d2 = 0;
      tree.knnSearch(queries[i].data(), 1, &index, &d2);
      // Recompute in double: the float squared distance loses precision for tiny offsets.
      out[i] = (queries[i].cast<double>() - reference[index].cast<double>()).norm();
    }
  });
  return out;
}

Sparsification sparsification_curve(const torch::Tensor& rel_error, const torch::Tensor& confidence, int steps) {
  if (steps < 1) throw std::invalid_argument("sparsification needs at least one step");
  const auto err = rel_error.reshape({-1}).to(torch::kFloat64);
  const auto conf = confidence.reshape({-1}).to(torch::kFloat64);
  if (err.numel() != conf.numel()) throw std::invalid_argument("sparsification: errors and confidences differ in count");
  Sparsification out;
  const int64_t n = err.numel();
  if (n == 0) return out;
  // Cumulative sums of the errors in each order: the mean of the first k is one lookup. Pixels of
  // equal confidence cannot be told apart, so each takes its group's mean error (the expected
  // curve over every order of the ties): a constant confidence gives a flat curve.
  const auto [sorted_conf, order] = conf.sort(/*stable=*/true, 0, /*descending=*/true);
  auto by_confidence = err.index_select(0, order);
  const auto [groups, group_of, group_size] = torch::unique_consecutive(sorted_conf, /*return_inverse=*/true, /*return_counts=*/true);
  if (groups.numel() < n) {
    const auto group_sum = torch::zeros({groups.numel()}, by_confidence.options()).index_add_(0, group_of, by_confidence);
    by_confidence = (group_sum / group_size.to(torch::kFloat64)).index_select(0, group_of);
  }
  const auto by_error = std::get<0>(err.sort(/*stable=*/true, 0, /*descending=*/false));
  const auto cum_conf = by_confidence.cumsum(0), cum_oracle = by_error.cumsum(0);
  const auto c = cum_conf.accessor<double, 1>(), o = cum_oracle.accessor<double, 1>();
  double gap = 0.0;
  for (int s = 1; s <= steps; ++s) {
    const int64_t k = std::max<int64_t>(1, static_cast<int64_t>(std::llround(static_cast<double>(n) * s / steps)));
    out.kept.push_back(static_cast<double>(s) / steps);
    out.abs_rel.push_back(c[k - 1] / k);
    out.oracle.push_back(o[k - 1] / k);
    gap += out.abs_rel.back() - out.oracle.back();
  }
  out.ause = gap / steps;
  return out;
}

PointCloud depth_map_points(const torch::Tensor& depth, const Camera& camera, int stride) {
  if (depth.dim() != 2) throw std::invalid_argument("depth_map_points: depth must be [H,W]");
  if (depth.size(0) != camera.height || depth.size(1) != camera.width) {
    throw std::invalid_argument("depth_map_points: the camera is " + std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                                ", the depth map " + std::to_string(depth.size(1)) + "x" + std::to_string(depth.size(0)));
  }
  if (stride < 1) throw std::invalid_argument("depth_map_points: stride must be >= 1");
  const auto d = depth.to(torch::kFloat32).contiguous();
  const auto a = d.accessor<float, 2>();
  PointCloud cloud;
  for (int64_t v = 0; v < d.size(0); v += stride) {
    for (int64_t u = 0; u < d.size(1); u += stride) {
      const float z = a[v][u];
      if (!(z > 0.0f) || !std::isfinite(z)) continue;
      cloud.points.push_back(camera.backproject(static_cast<double>(u), static_cast<double>(v), z).cast<float>());
    }
  }
  return cloud;
}

PointCloud downsample_min_spacing(const PointCloud& cloud, double spacing) {
  if (!(spacing > 0.0) || !std::isfinite(spacing)) throw std::invalid_argument("downsample spacing must be positive and finite");
  // Hash grid with cells of size `spacing`: a kept point's neighbours within `spacing` lie in the
  // 27 cells around it.
  struct KeyHash {
    size_t operator()(const std::array<int64_t, 3>& k) const {
      return static_cast<size_t>(k[0] * 73856093LL ^ k[1] * 19349663LL ^ k[2] * 83492791LL);
    }
  };
  std::unordered_map<std::array<int64_t, 3>, std::vector<uint32_t>, KeyHash> grid;
  const double s2 = spacing * spacing;
  std::vector<uint32_t> keep;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d p = cloud.points[i].cast<double>();
    if (!p.allFinite()) continue;
    const std::array<int64_t, 3> key = {static_cast<int64_t>(std::floor(p.x() / spacing)),
                                        static_cast<int64_t>(std::floor(p.y() / spacing)),
                                        static_cast<int64_t>(std::floor(p.z() / spacing))};
    bool close = false;
    for (int dx = -1; dx <= 1 && !close; ++dx)
      for (int dy = -1; dy <= 1 && !close; ++dy)
        for (int dz = -1; dz <= 1 && !close; ++dz) {
          auto it = grid.find({key[0] + dx, key[1] + dy, key[2] + dz});
          if (it == grid.end()) continue;
          for (uint32_t j : it->second)
            if ((cloud.points[j].cast<double>() - p).squaredNorm() < s2) {
              close = true;
              break;
            }
        }
    if (close) continue;
    grid[key].push_back(static_cast<uint32_t>(i));
    keep.push_back(static_cast<uint32_t>(i));
  }
  PointCloud out;
  const size_t n = cloud.size();
  for (uint32_t i : keep) {
    out.points.push_back(cloud.points[i]);
    if (cloud.colors.size() == n) out.colors.push_back(cloud.colors[i]);
    if (cloud.confidence.size() == n) out.confidence.push_back(cloud.confidence[i]);
    if (cloud.num_views.size() == n) out.num_views.push_back(cloud.num_views[i]);
  }
  return out;
}

CloudMetrics evaluate_cloud(const PointCloud& est_in, const PointCloud& gt_in, const CloudMetricsConfig& config) {
  check_thresholds(config.thresholds, "precision/recall thresholds");
  if (config.max_distance < 0.0 || !std::isfinite(config.max_distance)) throw std::invalid_argument("max_distance must be >= 0");
  if (config.downsample_spacing < 0.0 || !std::isfinite(config.downsample_spacing)) {
    throw std::invalid_argument("downsample_spacing must be >= 0");
  }
  if (gt_in.empty()) throw std::invalid_argument("evaluate_cloud: the ground-truth cloud is empty");
  const bool down = config.downsample_spacing > 0.0;
  const PointCloud est = down ? downsample_min_spacing(est_in, config.downsample_spacing) : est_in;
  const PointCloud gt = down ? downsample_min_spacing(gt_in, config.downsample_spacing) : gt_in;
  CloudMetrics m;
  m.est_points = est.size();
  m.gt_points = gt.size();
  m.thresholds = config.thresholds;
  const auto d_acc = nearest_distances(est.points, gt.points);
  const auto d_comp = est.empty() ? std::vector<double>() : nearest_distances(gt.points, est.points);
  const DistanceSummary acc = summarise(d_acc, config.max_distance), comp = summarise(d_comp, config.max_distance);
  m.accuracy_mean = acc.mean;
  m.accuracy_median = acc.median;
  m.accuracy_outliers = acc.outliers;
  m.completeness_mean = comp.mean;
  m.completeness_median = comp.median;
  m.completeness_outliers = est.empty() ? 1.0 : comp.outliers;
  m.overall = 0.5 * (acc.mean + comp.mean);
  for (double t : config.thresholds) {
    const double p = share_within(d_acc, t), r = share_within(d_comp, t);
    m.precision.push_back(p);
    m.recall.push_back(r);
    m.fscore.push_back(p + r > 0 ? 2 * p * r / (p + r) : 0.0);
  }
  return m;
}

}  // namespace umvs
