#include "unsup_mvs/core/fine_pass.h"

#include <torch/torch.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {

void FinePassConfig::validate() const {
  if (planes < 0 || planes % 8 != 0) {
    throw std::invalid_argument("fine pass planes must be 0 (off) or a positive multiple of 8, got " + std::to_string(planes));
  }
  if (!std::isfinite(span) || span <= 0) {
    throw std::invalid_argument("fine pass span must be > 0 plane intervals, got " + std::to_string(span));
  }
  if (resolution_divisor != 2 && resolution_divisor != 4) {
    throw std::invalid_argument("fine pass resolution divisor must be 2 or 4, got " + std::to_string(resolution_divisor));
  }
  if (first_pass_downscale != 1 && first_pass_downscale != 2) {
    throw std::invalid_argument("fine pass: first_pass_downscale must be 1 or 2, got " + std::to_string(first_pass_downscale));
  }
}

torch::Tensor fine_pass_hypotheses(const torch::Tensor& depth, const torch::Tensor& depth_values, DepthSampling sampling,
                                   const FinePassConfig& fine) {
  fine.validate();
  TORCH_CHECK(fine.enabled(), "fine_pass_hypotheses: the fine pass is off");
  TORCH_CHECK(depth.dim() == 3 && depth_values.dim() == 2 && depth_values.size(0) == depth.size(0) && depth_values.size(1) >= 2,
              "fine_pass_hypotheses: depth must be [B,h,w] and depth_values [B,D>=2]");
  const bool inverse = sampling == DepthSampling::kUniformInverseDepth;
  // In the sampling's coordinate s (depth, or 1/depth), where the first pass's planes are evenly spaced.
  const auto to_s = [inverse](const torch::Tensor& d) { return inverse ? d.reciprocal() : d; };
  const int64_t B = depth.size(0), D = depth_values.size(1), P = fine.planes;
  const auto first = to_s(depth_values.select(1, 0)).view({B, 1, 1, 1});
  const auto last = to_s(depth_values.select(1, D - 1)).view({B, 1, 1, 1});
  const auto lo = torch::minimum(first, last), hi = torch::maximum(first, last);
  const auto interval = (hi - lo) / static_cast<double>(D - 1);
  const auto half_width = interval * (fine.span / 2);
  // The window is kept inside the range (narrowed when it is wider than the range).
  const auto half = torch::minimum(half_width, (hi - lo) / 2);
  const auto centre = torch::clamp(to_s(depth.unsqueeze(1)), lo + half, hi - half);
  // Offsets from -1 to 1; in 1/depth the largest value is the nearest depth: reversed, so that
  // the hypotheses increase in depth as the first pass's planes do.
  auto offsets = torch::linspace(-1.0, 1.0, P, depth.options()).view({1, P, 1, 1});
  if (inverse) offsets = offsets.flip(1);
  const auto s = centre + offsets * half;
  return inverse ? s.reciprocal() : s;
}

torch::Tensor upsample2_naive(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "upsample2_naive: expected [B,C,h,w], got ", x.sizes());
  const auto interleave = [](const torch::Tensor& t, int64_t dim) {
    const int64_t n = t.size(dim);
    const auto next = torch::cat({t.narrow(dim, 1, n - 1), t.narrow(dim, n - 1, 1)}, dim);
    auto shape = t.sizes().vec();
    shape[dim] *= 2;
    return torch::stack({t, (t + next) * 0.5}, dim + 1).reshape(shape);
  };
  return interleave(interleave(x, 3), 2);
}

// The variance of the views' features over each hypothesis (MVSNet's cost volume) with torch ops:
// features [B,V,C,h,w]; proj [B,V,4,4] at that resolution; hypotheses [B,D] or [B,D,h,w]
//   -> [B,C,D,h,w]
torch::Tensor variance_volume_by_warps(const torch::Tensor& features, const torch::Tensor& proj,
                                       const torch::Tensor& hypotheses, FeatureWarp warp) {
  const int64_t V = features.size(1), D = hypotheses.size(1);
  const auto ref = features.select(1, 0).unsqueeze(2);
  auto sum = ref.expand({-1, -1, D, -1, -1}).clone();
  auto sq_sum = (ref * ref).expand({-1, -1, D, -1, -1}).clone();
  for (int64_t v = 1; v < V; ++v) {
    const auto warped = homography_warp(features.select(1, v), proj.select(1, v), proj.select(1, 0), hypotheses, warp);
    sum += warped;
    sq_sum.addcmul_(warped, warped);
  }
  const double n = static_cast<double>(V);
  return sq_sum.div_(n).sub_(sum.div_(n).square());
}

}  // namespace umvs
