#include "unsup_mvs/core/depth_completion.h"

#include <ATen/ATen.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace umvs {

namespace {
// Weight of an estimate below the floor against one above it: small enough that the confident
// pixels decide, large enough that every pixel stays tied to something (the system stays
// positive definite even in a region no confident pixel reaches).
constexpr double kUnconfidentWeight = 1e-3;
constexpr int kMaxIterations = 2000;
constexpr double kRelativeTolerance = 1e-6;

bool usable(float d) { return std::isfinite(d) && d > 0.0f; }
}  // namespace

void DepthCompletionConfig::validate() const {
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    throw std::invalid_argument("depth completion: min_confidence must be in [0,1] (0 = off), got " +
                                std::to_string(min_confidence));
  }
  if (!(edge_sigma > 0.0 && std::isfinite(edge_sigma))) {
    throw std::invalid_argument("depth completion: edge_sigma must be > 0, got " + std::to_string(edge_sigma));
  }
}

torch::Tensor complete_depth(const torch::Tensor& depth, const torch::Tensor& confidence, const torch::Tensor& guide,
                             const DepthCompletionConfig& config, DepthCompletionStats* stats) {
  config.validate();
  if (depth.dim() != 2 || confidence.sizes() != depth.sizes() || guide.sizes() != depth.sizes()) {
    throw std::invalid_argument("depth completion: depth, confidence and guide must be [h,w] of one size");
  }
  const auto d_t = depth.to(torch::kCPU, torch::kFloat32).contiguous();
  const auto c_t = confidence.to(torch::kCPU, torch::kFloat32).contiguous();
  const auto g_t = guide.to(torch::kCPU, torch::kFloat32).contiguous();
  const int64_t h = depth.size(0), w = depth.size(1), n = h * w;
  const float* d = d_t.data_ptr<float>();
  const float* c = c_t.data_ptr<float>();
  const float* g = g_t.data_ptr<float>();

  // Data weights, and the initial guess / right-hand side in inverse depth.
  std::vector<double> a(n, 0.0), x0(n, 0.0);
  int64_t valid = 0, below = 0;
  for (int64_t i = 0; i < n; ++i) {
    if (!usable(d[i])) continue;
    ++valid;
    x0[i] = 1.0 / d[i];
    const bool confident = c[i] >= config.min_confidence;
    a[i] = confident ? 1.0 : kUnconfidentWeight;
    if (!confident) ++below;
  }
  if (stats) *stats = DepthCompletionStats{valid ? double(below) / valid : 0.0, 0, true};
  auto result = d_t.clone();
  if (below == 0 || below == valid) return result;  // nothing to complete, or nothing to complete from

  // Edge-aware smoothness between 4-neighbours that both hold a usable depth.
  const double inv_two_sigma_sq = 1.0 / (2.0 * config.edge_sigma * config.edge_sigma);
  std::vector<double> wx(n, 0.0), wy(n, 0.0);  // to the right / below neighbour
  for (int64_t y = 0; y < h; ++y) {
    for (int64_t x = 0; x < w; ++x) {
      const int64_t i = y * w + x;
      if (a[i] == 0.0) continue;
      if (x + 1 < w && a[i + 1] != 0.0) wx[i] = std::exp(-(g[i + 1] - g[i]) * (g[i + 1] - g[i]) * inv_two_sigma_sq);
      if (y + 1 < h && a[i + w] != 0.0) wy[i] = std::exp(-(g[i + w] - g[i]) * (g[i + w] - g[i]) * inv_two_sigma_sq);
    }
  }
  const auto apply = [&](const std::vector<double>& v, std::vector<double>& out) {
    for (int64_t i = 0; i < n; ++i) out[i] = a[i] * v[i];
    for (int64_t i = 0; i < n; ++i) {
      if (wx[i] != 0.0) {
        const double f = wx[i] * (v[i] - v[i + 1]);
        out[i] += f;
        out[i + 1] -= f;
      }
      if (wy[i] != 0.0) {
        const double f = wy[i] * (v[i] - v[i + w]);
        out[i] += f;
        out[i + w] -= f;
      }
    }
  };
  std::vector<double> diag(a);  // Jacobi preconditioner
  for (int64_t i = 0; i < n; ++i) {
    diag[i] += wx[i] + wy[i];
    if (i + 1 < n) diag[i + 1] += wx[i];
    if (i + w < n) diag[i + w] += wy[i];
  }

  // Preconditioned conjugate gradient on (diag(a) + L) x = a * x0, from x0.
  std::vector<double> x(x0), r(n), z(n), p(n), q(n);
  apply(x, q);
  double b_norm_sq = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    const double b = a[i] * x0[i];
    b_norm_sq += b * b;
    r[i] = b - q[i];
  }
  double rz = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    z[i] = diag[i] > 0.0 ? r[i] / diag[i] : 0.0;
    p[i] = z[i];
    rz += r[i] * z[i];
  }
  const double tolerance_sq = kRelativeTolerance * kRelativeTolerance * b_norm_sq;
  int it = 0;
  bool converged = false;
  for (; it < kMaxIterations; ++it) {
    double r_sq = 0.0;
    for (int64_t i = 0; i < n; ++i) r_sq += r[i] * r[i];
    if (r_sq <= tolerance_sq) {
      converged = true;
      break;
    }
    apply(p, q);
    double pq = 0.0;
    for (int64_t i = 0; i < n; ++i) pq += p[i] * q[i];
    if (!(pq > 0.0)) break;
    const double alpha = rz / pq;
    double rz_next = 0.0;
    for (int64_t i = 0; i < n; ++i) {
      x[i] += alpha * p[i];
      r[i] -= alpha * q[i];
      z[i] = diag[i] > 0.0 ? r[i] / diag[i] : 0.0;
      rz_next += r[i] * z[i];
    }
    const double beta = rz_next / rz;
    rz = rz_next;
    for (int64_t i = 0; i < n; ++i) p[i] = z[i] + beta * p[i];
  }
  if (stats) {
    stats->iterations = it;
    stats->converged = converged;
  }

  float* out = result.data_ptr<float>();
  for (int64_t i = 0; i < n; ++i) {
    // An inverse depth that is not positive cannot be a depth: keep the network's estimate there.
    if (a[i] != 0.0 && x[i] > 0.0) out[i] = static_cast<float>(1.0 / x[i]);
  }
  return result;
}

}  // namespace umvs
