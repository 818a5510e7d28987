#include "unsup_mvs/core/depth_completion.h"

#include <ATen/ATen.h>

#include <algorithm>
#include <cmath>
#include <utility>
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
// A coarser grid's solve is only a starting point for the finer one: a looser tolerance will do.
constexpr double kCoarseRelativeTolerance = 1e-4;
// Grids are halved while both sides keep at least this many pixels.
constexpr int64_t kMinCoarseSide = 16;

bool usable(float d) { return std::isfinite(d) && d > 0.0f; }

// (diag(a) + L) x = a * target on an h x w grid, L the Laplacian of the edge weights wx (to the
// right neighbour) and wy (to the one below). a = 0 marks a pixel outside the problem.
struct GridSystem {
  int64_t h = 0, w = 0;
  std::vector<double> a, target, wx, wy;
};

// The same energy over 2x2 blocks, each block one unknown: data weights add up (their targets
// average by weight), and the edges that cross from one block to the next add up, halved so that
// a smooth field costs about what it costs on the finer grid (its steps are twice as long there).
GridSystem coarsen(const GridSystem& fine) {
  GridSystem c;
  c.h = (fine.h + 1) / 2;
  c.w = (fine.w + 1) / 2;
  const int64_t n = c.h * c.w;
  c.a.assign(n, 0.0);
  c.target.assign(n, 0.0);
  c.wx.assign(n, 0.0);
  c.wy.assign(n, 0.0);
  for (int64_t y = 0; y < fine.h; ++y) {
    for (int64_t x = 0; x < fine.w; ++x) {
      const int64_t i = y * fine.w + x, I = (y / 2) * c.w + x / 2;
      c.a[I] += fine.a[i];
      c.target[I] += fine.a[i] * fine.target[i];
      if (x % 2 == 1) c.wx[I] += 0.5 * fine.wx[i];
      if (y % 2 == 1) c.wy[I] += 0.5 * fine.wy[i];
    }
  }
  for (int64_t I = 0; I < n; ++I) {
    if (c.a[I] > 0.0) c.target[I] /= c.a[I];
  }
  return c;
}

// Preconditioned (Jacobi) conjugate gradient from x; returns the iterations and whether the
// residual fell below tolerance times the right-hand side's norm.
std::pair<int, bool> solve(const GridSystem& s, double tolerance, std::vector<double>& x) {
  const int64_t n = s.h * s.w, w = s.w;
  const auto& a = s.a;
  const auto& wx = s.wx;
  const auto& wy = s.wy;
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
  std::vector<double> diag(a);
  for (int64_t i = 0; i < n; ++i) {
    diag[i] += wx[i] + wy[i];
    if (i + 1 < n) diag[i + 1] += wx[i];
    if (i + w < n) diag[i + w] += wy[i];
  }
  std::vector<double> r(n), z(n), p(n), q(n);
  apply(x, q);
  double b_norm_sq = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    const double b = a[i] * s.target[i];
    b_norm_sq += b * b;
    r[i] = b - q[i];
  }
  double rz = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    z[i] = diag[i] > 0.0 ? r[i] / diag[i] : 0.0;
    p[i] = z[i];
    rz += r[i] * z[i];
  }
  const double tolerance_sq = tolerance * tolerance * b_norm_sq;
  for (int it = 0; it < kMaxIterations; ++it) {
    double r_sq = 0.0;
    for (int64_t i = 0; i < n; ++i) r_sq += r[i] * r[i];
    if (r_sq <= tolerance_sq) return {it, true};
    apply(p, q);
    double pq = 0.0;
    for (int64_t i = 0; i < n; ++i) pq += p[i] * q[i];
    if (!(pq > 0.0)) return {it, false};
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
  return {kMaxIterations, false};
}

// A starting point for `s`: its targets, or, on a grid large enough to halve, the solution of the
// coarser system spread back over each 2x2 block. Conjugate gradient needs about as many
// iterations as the widest gap it must fill is pixels wide; from the coarse solution only the
// fine detail is left to it.
std::vector<double> initial_guess(const GridSystem& s) {
  std::vector<double> x(s.target);
  if (s.h < 2 * kMinCoarseSide || s.w < 2 * kMinCoarseSide) return x;
  const GridSystem coarse = coarsen(s);
  std::vector<double> xc = initial_guess(coarse);
  solve(coarse, kCoarseRelativeTolerance, xc);
  // Bilinear between the blocks' centres, over the blocks that hold any pixel of the problem.
  for (int64_t y = 0; y < s.h; ++y) {
    const double v = std::clamp((y - 0.5) / 2.0, 0.0, double(coarse.h - 1));
    const int64_t y0 = static_cast<int64_t>(v), y1 = std::min(y0 + 1, coarse.h - 1);
    for (int64_t x_ = 0; x_ < s.w; ++x_) {
      const int64_t i = y * s.w + x_;
      if (s.a[i] == 0.0) continue;
      const double u = std::clamp((x_ - 0.5) / 2.0, 0.0, double(coarse.w - 1));
      const int64_t x0 = static_cast<int64_t>(u), x1 = std::min(x0 + 1, coarse.w - 1);
      const double fu = u - x0, fv = v - y0;
      double sum = 0.0, weight = 0.0;
      for (const auto& [I, k] : {std::pair{y0 * coarse.w + x0, (1 - fu) * (1 - fv)}, {y0 * coarse.w + x1, fu * (1 - fv)},
                                 {y1 * coarse.w + x0, (1 - fu) * fv}, {y1 * coarse.w + x1, fu * fv}}) {
        if (coarse.a[I] == 0.0 || k == 0.0) continue;
        sum += k * xc[I];
        weight += k;
      }
      if (weight > 0.0) x[i] = sum / weight;
    }
  }
  return x;
}
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

  // Data weights, and the targets in inverse depth.
  GridSystem system;
  system.h = h;
  system.w = w;
  system.a.assign(n, 0.0);
  system.target.assign(n, 0.0);
  auto& a = system.a;
  int64_t valid = 0, below = 0;
  for (int64_t i = 0; i < n; ++i) {
    if (!usable(d[i])) continue;
    ++valid;
    system.target[i] = 1.0 / d[i];
    const bool confident = c[i] >= config.min_confidence;
    a[i] = confident ? 1.0 : kUnconfidentWeight;
    if (!confident) ++below;
  }
  if (stats) *stats = DepthCompletionStats{valid ? double(below) / valid : 0.0, 0, true};
  auto result = d_t.clone();
  if (below == 0 || below == valid) return result;  // nothing to complete, or nothing to complete from

  // Edge-aware smoothness between 4-neighbours that both hold a usable depth.
  const double inv_two_sigma_sq = 1.0 / (2.0 * config.edge_sigma * config.edge_sigma);
  system.wx.assign(n, 0.0);  // to the right neighbour
  system.wy.assign(n, 0.0);  // to the one below
  for (int64_t y = 0; y < h; ++y) {
    for (int64_t x = 0; x < w; ++x) {
      const int64_t i = y * w + x;
      if (a[i] == 0.0) continue;
      if (x + 1 < w && a[i + 1] != 0.0) {
        system.wx[i] = std::exp(-(g[i + 1] - g[i]) * (g[i + 1] - g[i]) * inv_two_sigma_sq);
      }
      if (y + 1 < h && a[i + w] != 0.0) {
        system.wy[i] = std::exp(-(g[i + w] - g[i]) * (g[i + w] - g[i]) * inv_two_sigma_sq);
      }
    }
  }

  std::vector<double> x = initial_guess(system);
  const auto [iterations, converged] = solve(system, kRelativeTolerance, x);
  if (stats) {
    stats->iterations = iterations;
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
