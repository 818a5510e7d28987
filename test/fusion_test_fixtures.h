// The analytic scene of the fusion tests (test_fusion.cpp, test_streaming_fusion.cpp): a ground
// plane z = 0 with a sphere on it, seen by a ring of cameras, with ray-cast ground-truth depth maps
// and the checks of fused points against the exact surface.
#pragma once

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <vector>

#include "unsup_mvs/core/fusion.h"

namespace umvs::test {

inline const Eigen::Vector3d kSphereCentre(0.0, 0.0, 0.3);
inline const double kSphereRadius = 0.3;

inline Camera look_at(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, int w = 64, int h = 48) {
  Eigen::Matrix3d K;
  K << 60, 0, (w - 1) / 2.0, 0, 60, (h - 1) / 2.0, 0, 0, 1;
  return Camera::look_at(centre, target, K, w, h);
}

// z-depth of the nearest surface (plane or sphere) for every pixel.  -> [H,W] float32
inline torch::Tensor render_depth(const Camera& cam) {
  const int H = cam.height, W = cam.width;
  auto xs = torch::arange(W, torch::kFloat64).view({1, W}).expand({H, W});
  auto ys = torch::arange(H, torch::kFloat64).view({H, 1}).expand({H, W});
  const Eigen::Matrix3d M = cam.R().transpose() * cam.K.inverse();  // pixel -> world ray (camera z = 1)
  auto ray = [&](int r) { return M(r, 0) * xs + M(r, 1) * ys + M(r, 2); };
  auto dx = ray(0), dy = ray(1), dz = ray(2);
  const Eigen::Vector3d C = cam.center();
  const double inf = std::numeric_limits<double>::infinity();
  auto s_plane = -C.z() / dz;
  s_plane = torch::where(s_plane > 0, s_plane, torch::full_like(s_plane, inf));
  const Eigen::Vector3d oc = C - kSphereCentre;
  auto a = dx * dx + dy * dy + dz * dz;
  auto b = 2 * (dx * oc.x() + dy * oc.y() + dz * oc.z());
  const double c = oc.squaredNorm() - kSphereRadius * kSphereRadius;
  auto disc = b * b - 4 * a * c;
  auto s_sphere = (-b - torch::sqrt(disc.clamp_min(0))) / (2 * a);
  s_sphere = torch::where((disc > 0) & (s_sphere > 0), s_sphere, torch::full_like(s_sphere, inf));
  auto s = torch::minimum(s_plane, s_sphere);
  return torch::where(torch::isfinite(s), s, torch::zeros_like(s)).to(torch::kFloat32);
}

// Distance of points [N,3] to the scene surface (plane z = 0 or sphere).  -> [N]
inline torch::Tensor surface_distance(const torch::Tensor& pts) {
  auto c = torch::tensor({kSphereCentre.x(), kSphereCentre.y(), kSphereCentre.z()}, torch::kFloat32);
  auto d_sphere = ((pts - c).norm(2, 1) - kSphereRadius).abs();
  auto d_plane = pts.select(1, 2).abs();
  return torch::minimum(d_sphere, d_plane);
}

// Accuracy the fusion guarantees by construction: every point's depth is within
// max_relative_depth (1%) of the reference depth, i.e. < 2.5 cm at the ~2.3 m of the farthest
// pixels. Bilinear interpolation of the source depth (exact only for fronto-parallel surfaces)
// and mixed depths at the sphere's silhouette average in a few millimetres at 64x48 pixels, so
// the typical error is far smaller.
inline void expect_accurate(const torch::Tensor& pts, double median = 2e-4, double p99 = 4e-3, double max = 0.025) {
  ASSERT_GT(pts.size(0), 0);
  auto err = surface_distance(pts);
  EXPECT_LT(err.median().item<double>(), median);
  EXPECT_LT(err.quantile(0.99).item<double>(), p99);
  EXPECT_LT(err.max().item<double>(), max);
}

inline torch::Tensor to_tensor(const PointCloud& cloud) {
  auto t = torch::empty({static_cast<int64_t>(cloud.size()), 3}, torch::kFloat32);
  for (size_t i = 0; i < cloud.size(); ++i)
    for (int k = 0; k < 3; ++k) t[i][k] = cloud.points[i][k];
  return t;
}

inline std::vector<FusionView> ring_views(int n = 8) {
  std::vector<FusionView> views;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * M_PI * i / n * 0.5;  // half a ring: neighbours overlap well
    FusionView v;
    v.id = i;
    v.camera = look_at({1.6 * std::cos(a), 1.6 * std::sin(a), 1.2}, {0, 0, 0.15});
    v.depth = render_depth(v.camera);
    views.push_back(v);
  }
  return views;
}

inline std::vector<std::vector<int>> all_others(size_t n) {
  std::vector<std::vector<int>> s(n);
  for (size_t i = 0; i < n; ++i)
    for (size_t j = 0; j < n; ++j)
      if (i != j) s[i].push_back(static_cast<int>(j));
  return s;
}

}  // namespace umvs::test
