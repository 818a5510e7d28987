#include "unsup_mvs/core/image_ops.h"

#include <torch/torch.h>

namespace umvs {

namespace F = torch::nn::functional;

torch::Tensor rgb8_to_float(const torch::Tensor& rgb8) {
  TORCH_CHECK(rgb8.dim() == 3 && rgb8.size(2) == 3, "expected uint8 [H,W,3], got ", rgb8.sizes());
  return rgb8.permute({2, 0, 1}).to(torch::kFloat32).div(255).contiguous();
}

torch::Tensor float_to_rgb8(const torch::Tensor& image) {
  return image.detach().mul(255).round().clamp(0, 255).to(torch::kUInt8).permute({1, 2, 0}).contiguous();
}

torch::Tensor resize_image(const torch::Tensor& image, int width, int height) {
  const bool batched = image.dim() == 4;
  auto x = batched ? image : image.unsqueeze(0);
  if (x.size(2) == height && x.size(3) == width) return image;
  const bool shrink = height <= x.size(2) && width <= x.size(3);
  auto opts = F::InterpolateFuncOptions().size(std::vector<int64_t>{height, width});
  x = shrink ? F::interpolate(x, opts.mode(torch::kArea))
             : F::interpolate(x, opts.mode(torch::kBilinear).align_corners(false));
  return batched ? x : x.squeeze(0);
}

torch::Tensor apply_network_resize(const torch::Tensor& image, const NetworkResize& plan) {
  auto x = resize_image(image, plan.scaled_width, plan.scaled_height);
  return x.slice(-2, plan.crop_y, plan.crop_y + plan.height).slice(-1, plan.crop_x, plan.crop_x + plan.width).contiguous();
}

torch::Tensor colorize(const torch::Tensor& values, double lo, double hi, const torch::Tensor& valid) {
  auto v = values.detach().to(torch::kCPU, torch::kFloat32);
  auto t = ((v - lo) / std::max(hi - lo, 1e-12)).clamp(0, 1);
  // jet: r, g, b are tents centred at 0.75, 0.5, 0.25
  auto ramp = [&](double centre) { return (1.5 - (4 * t - 4 * centre).abs()).clamp(0, 1); };
  auto rgb = torch::stack({ramp(0.75), ramp(0.5), ramp(0.25)}, 2);
  auto ok = torch::isfinite(v);
  if (valid.defined()) ok = ok & valid.to(torch::kCPU).to(torch::kBool);
  rgb = rgb * ok.unsqueeze(2);
  return rgb.mul(255).round().to(torch::kUInt8);
}

}  // namespace umvs
