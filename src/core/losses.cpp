#include "unsup_mvs/core/losses.h"

#include <torch/torch.h>

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "unsup_mvs/core/geometry.h"

namespace umvs {

namespace F = torch::nn::functional;

const char* to_string(PhotometricTerm t) { return t == PhotometricTerm::kNaive ? "naive" : "first-order"; }

LossConfig LossConfig::paper() { return LossConfig{}; }

LossConfig LossConfig::authors_code() {
  LossConfig c;
  c.alpha = 12.0;
  c.beta = 6.0;
  c.gamma = 0.18;
  c.huber_delta_intensity = 0.6;
  c.huber_delta_gradient = 0.2;
  c.normalize_images = true;
  return c;
}

void LossConfig::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("loss config: " + what); };
  if (top_k < 0) bad("top_k must be >= 0 (0 = all views), got " + std::to_string(top_k));
  if (!(huber_delta_intensity >= 0) || !(huber_delta_gradient >= 0)) bad("Huber thresholds must be >= 0");
  if (!(invalid_value > 0)) bad("invalid_value must be positive");
  if (ssim_views < 0) bad("ssim_views must be >= 0");
  for (double w : {alpha, beta, gamma}) {
    if (!std::isfinite(w) || w < 0) bad("weights alpha, beta, gamma must be finite and >= 0");
  }
}

std::string LossConfig::to_string() const {
  std::ostringstream s;
  s << umvs::to_string(term) << ", top-K " << (top_k == 0 ? std::string("all") : std::to_string(top_k))
    << ", alpha " << alpha << " beta " << beta << " gamma " << gamma << ", Huber " << huber_delta_intensity << "/"
    << huber_delta_gradient << (normalize_images ? ", normalised images" : "");
  return s.str();
}

namespace {

// Forward differences along x and y, zero in the last column / row.  [B,C,H,W] -> same shape
torch::Tensor grad_x(const torch::Tensor& x) {
  return F::pad(x.narrow(3, 1, x.size(3) - 1) - x.narrow(3, 0, x.size(3) - 1), F::PadFuncOptions({0, 1, 0, 0}));
}
torch::Tensor grad_y(const torch::Tensor& x) {
  return F::pad(x.narrow(2, 1, x.size(2) - 1) - x.narrow(2, 0, x.size(2) - 1), F::PadFuncOptions({0, 0, 0, 1}));
}

// Smooth-L1 form of the Huber penalty: x^2 / (2 delta) below delta, |x| - delta/2 above, so
// delta = 0 is exactly L1 and the penalty has the L1 scale for large residuals.
torch::Tensor huber(const torch::Tensor& x, double delta) {
  auto a = x.abs();
  if (delta <= 0) return a;
  return torch::where(a < delta, 0.5 * a * a / delta, a - 0.5 * delta);
}

// Per image zero mean, unit standard deviation.  [B,C,H,W]
torch::Tensor normalize_per_image(const torch::Tensor& x) {
  auto flat = x.flatten(1);
  auto mean = flat.mean(1).view({-1, 1, 1, 1});
  auto std = flat.std(1).view({-1, 1, 1, 1}).clamp_min(1e-6);
  return (x - mean) / std;
}

torch::Tensor avg3(const torch::Tensor& x) {
  return F::avg_pool2d(F::pad(x, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate)),
                       F::AvgPool2dFuncOptions(3).stride(1));
}

}  // namespace

LossMap photometric_loss_map(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid,
                             const LossConfig& config) {
  TORCH_CHECK(ref.sizes() == warped.sizes(), "photometric_loss_map: ref ", ref.sizes(), " vs warped ", warped.sizes());
  const auto diff = ref - warped;
  if (config.term == PhotometricTerm::kNaive) {
    return {diff.abs().mean(1), valid.squeeze(1)};
  }
  auto loss = huber(diff, config.huber_delta_intensity).mean(1) +
              (huber(grad_x(ref) - grad_x(warped), config.huber_delta_gradient) +
               huber(grad_y(ref) - grad_y(warped), config.huber_delta_gradient))
                  .mean(1);
  // A gradient reads the pixel and its right / lower neighbour: all three must be valid. The last
  // column and row have no neighbour and are excluded.
  auto v = valid.squeeze(1);
  const int64_t H = v.size(1), W = v.size(2);
  auto right = F::pad(v.narrow(2, 1, W - 1), F::PadFuncOptions({0, 1, 0, 0}));
  auto below = F::pad(v.narrow(1, 1, H - 1), F::PadFuncOptions({0, 0, 0, 1}));
  return {loss, v * right * below};
}

namespace {

// Eq. 5's selection: per pixel the top_k (0 = all) smallest entries over the views (dim 1), invalid
// entries counting as invalid_value, and which of those kept are valid; values are 0 where invalid.
//   losses, valid [B,M,H,W]  -> both [B,k,H,W]
struct KeptEntries {
  torch::Tensor values;
  torch::Tensor valid;
};
KeptEntries smallest_valid_entries(const torch::Tensor& losses, const torch::Tensor& valid, int top_k,
                                   double invalid_value) {
  TORCH_CHECK(losses.sizes() == valid.sizes() && losses.dim() == 4, "top-K selection: losses and valid must be [B,M,H,W]");
  const int64_t M = losses.size(1);
  if (top_k < 0 || top_k > M) {
    throw std::invalid_argument("top_k must be in 0.." + std::to_string(M) + " (0 = all views), got " + std::to_string(top_k));
  }
  const int64_t k = top_k == 0 ? M : top_k;
  auto masked = torch::where(valid > 0.5, losses, torch::full_like(losses, invalid_value));
  auto [values, indices] = masked.topk(k, /*dim=*/1, /*largest=*/false, /*sorted=*/true);
  auto kept_valid = valid.gather(1, indices);
  return {values * kept_valid, kept_valid};
}

}  // namespace

torch::Tensor top_k_aggregate(const torch::Tensor& losses, const torch::Tensor& valid, int top_k,
                              double invalid_value) {
  const KeptEntries kept = smallest_valid_entries(losses, valid, top_k, invalid_value);
  return kept.values.sum() / kept.valid.sum().clamp_min(1.0);
}

SsimLossMap ssim_loss_map(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid) {
  const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
  auto x = ref * valid, y = warped * valid;
  auto mu_x = avg3(x), mu_y = avg3(y);
  auto sigma_x = avg3(x * x) - mu_x * mu_x;
  auto sigma_y = avg3(y * y) - mu_y * mu_y;
  auto sigma_xy = avg3(x * y) - mu_x * mu_y;
  auto ssim = ((2 * mu_x * mu_y + c1) * (2 * sigma_xy + c2)) /
              ((mu_x * mu_x + mu_y * mu_y + c1) * (sigma_x + sigma_y + c2));
  SsimLossMap map;
  map.loss = ((1 - ssim) / 2).clamp(0, 1).mean(1, /*keepdim=*/true);
  map.window_valid = (avg3(valid) > 0.999).to(map.loss.scalar_type());
  return map;
}

torch::Tensor ssim_loss(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid) {
  const SsimLossMap map = ssim_loss_map(ref, warped, valid);
  return (map.loss * map.window_valid).sum() / map.window_valid.sum().clamp_min(1.0);
}

torch::Tensor local_std(const torch::Tensor& image) {
  const auto mu = avg3(image);
  return (avg3(image * image) - mu * mu).clamp_min(0).sqrt().mean(1, /*keepdim=*/true);
}

torch::Tensor supervised_depth_loss(const torch::Tensor& depth, const torch::Tensor& gt,
                                    const torch::Tensor& depth_values, DepthSampling sampling) {
  TORCH_CHECK(depth.sizes() == gt.sizes(), "depth and ground truth differ in shape: ", depth.sizes(), " vs ",
              gt.sizes());
  const auto mask = gt > 0;
  if (!mask.any().item<bool>()) return depth.sum() * 0.0;  // keeps the graph (and the device)
  // Ground-truth-less pixels get the estimate itself as target, so that 1/gt stays finite there.
  const auto target = torch::where(mask, gt, depth.detach());
  const auto est_index = depth_to_plane_index(depth, depth_values, sampling).masked_select(mask);
  const auto gt_index = depth_to_plane_index(target, depth_values, sampling).masked_select(mask);
  return torch::nn::functional::smooth_l1_loss(est_index, gt_index);
}

torch::Tensor normalized_plane_entropy(const torch::Tensor& prob) {
  TORCH_CHECK(prob.dim() == 4 && prob.size(1) >= 2, "probability volume must be [B,D,H,W] with D >= 2, got ",
              prob.sizes());
  // p log p -> 0 as p -> 0; the clamp keeps log finite (and its gradient) at exact zeros.
  const auto plogp = prob * torch::log(prob.clamp_min(1e-12));
  return -plogp.sum(1) / std::log(static_cast<double>(prob.size(1)));
}

torch::Tensor smoothness_loss(const torch::Tensor& depth, const torch::Tensor& image) {
  auto d = depth.unsqueeze(1);
  d = d / d.mean({2, 3}, /*keepdim=*/true).clamp_min(1e-6);
  auto wx = torch::exp(-grad_x(image).abs().mean(1, true));
  auto wy = torch::exp(-grad_y(image).abs().mean(1, true));
  const int64_t H = d.size(2), W = d.size(3);
  auto sx = (grad_x(d).abs() * wx).narrow(3, 0, W - 1).mean();
  auto sy = (grad_y(d).abs() * wy).narrow(2, 0, H - 1).mean();
  return sx + sy;
}

PlaneLosses plane_photometric_losses(const torch::Tensor& ref_image, const torch::Tensor& src_images,
                                     const torch::Tensor& K_ref, const torch::Tensor& K_src,
                                     const torch::Tensor& T_src_ref, const torch::Tensor& depth_values,
                                     const LossConfig& config) {
  config.validate();
  TORCH_CHECK(ref_image.dim() == 4 && src_images.dim() == 5 && depth_values.dim() == 2,
              "plane_photometric_losses: ref [B,3,H,W], sources [B,M,3,H,W], depth_values [B,D]");
  torch::NoGradGuard no_grad;
  const int64_t B = ref_image.size(0), H = ref_image.size(2), W = ref_image.size(3);
  const int64_t M = src_images.size(1), D = depth_values.size(1);
  const auto ref = config.normalize_images ? normalize_per_image(ref_image) : ref_image;
  std::vector<torch::Tensor> sources;
  for (int64_t m = 0; m < M; ++m) {
    const auto src = src_images.select(1, m);
    sources.push_back(config.normalize_images ? normalize_per_image(src) : src);
  }
  std::vector<torch::Tensor> plane_loss, plane_valid;
  for (int64_t d = 0; d < D; ++d) {
    const auto depth = depth_values.select(1, d).view({B, 1, 1}).expand({B, H, W}).contiguous();
    std::vector<torch::Tensor> losses, valids;
    for (int64_t m = 0; m < M; ++m) {
      const auto w = inverse_warp(sources[m], K_ref, K_src.select(1, m), T_src_ref.select(1, m), depth);
      const auto map = photometric_loss_map(ref, w.warped, w.valid, config);
      losses.push_back(map.loss);
      valids.push_back(map.valid);
    }
    const KeptEntries kept =
        smallest_valid_entries(torch::stack(losses, 1), torch::stack(valids, 1), config.top_k, config.invalid_value);
    const auto count = kept.valid.sum(1);
    plane_loss.push_back(kept.values.sum(1) / count.clamp_min(1.0));
    plane_valid.push_back((count > 0).to(kept.values.scalar_type()));
  }
  return {torch::stack(plane_loss, 1), torch::stack(plane_valid, 1)};
}

torch::Tensor expected_plane_loss(const torch::Tensor& prob, const PlaneLosses& planes) {
  TORCH_CHECK(prob.sizes() == planes.loss.sizes() && prob.sizes() == planes.valid.sizes(),
              "expected_plane_loss: probabilities ", prob.sizes(), " and plane losses ", planes.loss.sizes(), " differ");
  // Only pixels every plane can judge: a plane whose warp leaves the images is not a worse depth.
  const auto pixel_valid = std::get<0>(planes.valid.min(1));
  const auto expected = (prob * planes.loss * planes.valid).sum(1);
  return (expected * pixel_valid).sum() / pixel_valid.sum().clamp_min(1.0);
}

LossTerms unsupervised_loss(const torch::Tensor& ref_image, const torch::Tensor& src_images, const torch::Tensor& K_ref,
                            const torch::Tensor& K_src, const torch::Tensor& T_src_ref, const torch::Tensor& depth,
                            const LossConfig& config) {
  config.validate();
  TORCH_CHECK(ref_image.dim() == 4 && src_images.dim() == 5, "unsupervised_loss: ref [B,3,H,W], sources [B,M,3,H,W]");
  TORCH_CHECK(depth.dim() == 3 && depth.size(1) == ref_image.size(2) && depth.size(2) == ref_image.size(3),
              "unsupervised_loss: depth ", depth.sizes(), " must be on the image grid ", ref_image.sizes());
  const int64_t M = src_images.size(1);
  if (config.top_k > M) {
    throw std::invalid_argument("top-K " + std::to_string(config.top_k) + " exceeds the " + std::to_string(M) + " loss views");
  }
  auto ref = config.normalize_images ? normalize_per_image(ref_image) : ref_image;
  std::vector<torch::Tensor> losses, valids;
  torch::Tensor ssim_sum = torch::zeros({}, depth.options());
  int ssim_count = 0;
  for (int64_t m = 0; m < M; ++m) {
    auto src = src_images.select(1, m);
    if (config.normalize_images) src = normalize_per_image(src);
    auto w = inverse_warp(src, K_ref, K_src.select(1, m), T_src_ref.select(1, m), depth);
    auto map = photometric_loss_map(ref, w.warped, w.valid, config);
    losses.push_back(map.loss);
    valids.push_back(map.valid);
    if (m < config.ssim_views) {
      ssim_sum = ssim_sum + ssim_loss(ref, w.warped, w.valid);
      ++ssim_count;
    }
  }
  const KeptEntries kept =
      smallest_valid_entries(torch::stack(losses, 1), torch::stack(valids, 1), config.top_k, config.invalid_value);
  LossTerms t;
  t.photometric = kept.values.sum() / kept.valid.sum().clamp_min(1.0);  // as top_k_aggregate
  t.ssim = ssim_count > 0 ? ssim_sum / ssim_count : ssim_sum;
  t.smoothness = smoothness_loss(depth, ref);
  t.total = config.alpha * t.photometric + config.beta * t.ssim + config.gamma * t.smoothness;
  t.valid_fraction = kept.valid.detach().mean();
  return t;
}

}  // namespace umvs
