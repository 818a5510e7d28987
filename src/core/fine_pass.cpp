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

void check_coarse_to_fine_inputs(const torch::Tensor& images, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, const FinePassConfig& fine,
                                 const torch::Tensor& proj_fine) {
  fine.validate();
  TORCH_CHECK(fine.enabled(), "coarse to fine: the fine pass is off (fine planes 0)");
  MvsNetImpl::check_inputs(images, proj, depth_values);
  TORCH_CHECK(proj_fine.sizes() == proj.sizes(), "coarse to fine: proj_fine must be [B,V,4,4] as proj, got ",
              proj_fine.sizes());
  const int64_t H = images.size(3), W = images.size(4);
  TORCH_CHECK(fine.first_pass_downscale == 1 || (H % 64 == 0 && W % 64 == 0),
              "coarse to fine: a first pass at half size needs the input's width and height to be multiples of 64, got ",
              W, "x", H);
}

std::pair<torch::Tensor, torch::Tensor> half_size_views(const torch::Tensor& images, const torch::Tensor& proj) {
  const int64_t B = images.size(0), V = images.size(1), H = images.size(3), W = images.size(4);
  auto half = torch::avg_pool2d(images.reshape({B * V, 3, H, W}), 2).view({B, V, 3, H / 2, W / 2});
  const auto row_scale = torch::tensor({0.5f, 0.5f, 1.0f, 1.0f}, proj.options()).view({1, 1, 4, 1});
  return {half, proj * row_scale};
}

FineGrid to_fine_grid(const torch::Tensor& depth, const torch::Tensor& confidence, const torch::Tensor& features,
                      const FinePassConfig& fine) {
  const auto up = [](const torch::Tensor& map) { return upsample2_naive(map.unsqueeze(1)).squeeze(1); };
  FineGrid grid{depth, confidence, features};
  if (fine.first_pass_downscale == 2) grid.depth = up(grid.depth), grid.confidence = up(grid.confidence);  // 1/8 -> 1/4
  if (fine.resolution_divisor == 2) {  // 1/4 -> 1/2
    const int64_t B = features.size(0), V = features.size(1), C = features.size(2), h = features.size(3), w = features.size(4);
    grid.features = upsample2_naive(features.reshape({B * V, C, h, w})).view({B, V, C, 2 * h, 2 * w});
    grid.depth = up(grid.depth), grid.confidence = up(grid.confidence);
  }
  return grid;
}

MvsOutput coarse_to_fine_forward(MvsNetImpl& model, const torch::Tensor& images, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, const FinePassConfig& fine,
                                 const torch::Tensor& proj_fine) {
  check_coarse_to_fine_inputs(images, proj, depth_values, fine, proj_fine);
  const FeatureWarp warp = model.config().feature_warp;
  const auto features = model.view_features(images);  // [B,V,32,H/4,W/4]
  auto [coarse_features, coarse_proj] = std::make_pair(features, proj);
  if (fine.first_pass_downscale == 2) {
    const auto [half_images, half_proj] = half_size_views(images, proj);
    coarse_features = model.view_features(half_images);
    coarse_proj = half_proj;
  }
  const auto coarse_volume = variance_volume_by_warps(coarse_features, coarse_proj, depth_values, warp);
  const auto coarse_prob = torch::softmax(model.cost_regularization->forward(coarse_volume), 1);
  MvsOutput out;
  out.depth_init = expected_depth(coarse_prob, depth_values);
  torch::Tensor confidence;
  {
    torch::NoGradGuard no_grad;
    confidence = photometric_confidence(coarse_prob);
  }
  // The hypotheses follow the first pass's depth without a gradient through it (CasMVSNet): each
  // pass learns from its own loss.
  const FineGrid grid = to_fine_grid(out.depth_init.detach(), confidence, features, fine);
  const auto hypotheses = fine_pass_hypotheses(grid.depth, depth_values, model.config().depth_sampling, fine);
  const auto fine_volume = variance_volume_by_warps(grid.features, proj_fine, hypotheses, warp);
  const auto fine_prob = torch::softmax(model.cost_regularization->forward(fine_volume), 1);
  out.depth = (fine_prob * hypotheses).sum(1);
  out.confidence = grid.confidence;
  return out;
}

}  // namespace umvs
