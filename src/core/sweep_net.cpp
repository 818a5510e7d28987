#include "unsup_mvs/core/sweep_net.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>

#include "feature_sampling.h"
#include "unsup_mvs/core/fine_pass.h"

namespace umvs {

namespace nn = torch::nn;
namespace F = torch::nn::functional;

ConvGnReLUImpl::ConvGnReLUImpl(int in, int out, int kernel, int stride) {
  conv = register_module(
      "conv", nn::Conv2d(nn::Conv2dOptions(in, out, kernel).stride(stride).padding(kernel / 2).bias(false)));
  norm = register_module("norm", nn::GroupNorm(nn::GroupNormOptions(std::max(1, out / 8), out)));
}

torch::Tensor ConvGnReLUImpl::forward(const torch::Tensor& x) { return torch::relu(norm(conv(x))); }

SweepFeatureNetImpl::SweepFeatureNetImpl() {
  // 5x5 stride-2 layers: output pixel i is centred on input pixel 2i (MVSNet's naive scaling).
  half0_ = register_module("half0", ConvGnReLU(3, kHalfChannels, 5, 2));
  half1_ = register_module("half1", ConvGnReLU(kHalfChannels, kHalfChannels));
  quarter0_ = register_module("quarter0", ConvGnReLU(kHalfChannels, kQuarterChannels, 5, 2));
  quarter1_ = register_module("quarter1", ConvGnReLU(kQuarterChannels, kQuarterChannels));
  matching_ = register_module("matching",
                              nn::Conv2d(nn::Conv2dOptions(kQuarterChannels, kMatchingChannels, 3).padding(1)));
}

SweepFeatures SweepFeatureNetImpl::forward(const torch::Tensor& image) {
  SweepFeatures f;
  f.half = half1_(half0_(image));
  f.quarter = quarter1_(quarter0_(f.half));
  f.matching = matching_(f.quarter);
  return f;
}

namespace {
// Channels of the encoder at 1/4, 1/8, 1/16 and 1/32 of the input.
constexpr int kEncoderChannels[4] = {48, 64, 96, 128};
constexpr int kQuarterDecoderChannels = 32, kHalfDecoderChannels = 24;
// The cost itself joins the logits, scaled: an untrained decoder then already picks the plane whose
// features match best (a cosine 0.1 higher is e^1 more likely), and training learns the corrections.
// Without it, 500 steps of the default model's recipe did not move the held-out depth.
constexpr double kCostLogitScale = 10.0;
}  // namespace

CostDecoder2DImpl::CostDecoder2DImpl(int num_depth) : num_depth_(num_depth) {
  const int* c = kEncoderChannels;
  encoder_.push_back(register_module("enc0", ConvGnReLU(num_depth + SweepFeatureNetImpl::kQuarterChannels, c[0])));
  for (int s = 1; s < 4; ++s) {
    encoder_.push_back(register_module("enc" + std::to_string(s) + "a", ConvGnReLU(c[s - 1], c[s], 3, 2)));
    encoder_.push_back(register_module("enc" + std::to_string(s) + "b", ConvGnReLU(c[s], c[s])));
  }
  up16_ = register_module("up16", ConvGnReLU(c[3] + c[2], c[2]));
  up8_ = register_module("up8", ConvGnReLU(c[2] + c[1], c[1]));
  up4_ = register_module("up4", ConvGnReLU(c[1] + c[0], kQuarterDecoderChannels));
  up2_ = register_module("up2", ConvGnReLU(kQuarterDecoderChannels + SweepFeatureNetImpl::kHalfChannels,
                                           kHalfDecoderChannels));
  logits_ = register_module("logits", nn::Conv2d(nn::Conv2dOptions(kHalfDecoderChannels, num_depth, 1)));
}

torch::Tensor CostDecoder2DImpl::forward(const torch::Tensor& cost, const torch::Tensor& quarter,
                                         const torch::Tensor& half) {
  TORCH_CHECK(cost.dim() == 4 && cost.size(1) == num_depth_, "the 2-D cost decoder was built for ", num_depth_,
              " planes, got a cost volume of shape ", cost.sizes());
  TORCH_CHECK(cost.size(2) % 8 == 0 && cost.size(3) % 8 == 0,
              "the 2-D cost decoder needs a 1/4-resolution grid in multiples of 8, got ", cost.size(2), "x",
              cost.size(3));
  auto x = encoder_[0](torch::cat({cost, quarter}, 1));
  std::vector<torch::Tensor> skips = {x};
  for (size_t i = 1; i < encoder_.size(); i += 2) {
    x = encoder_[i + 1](encoder_[i](x));
    skips.push_back(x);
  }
  x = up16_(torch::cat({upsample2_naive(x), skips[2]}, 1));
  x = up8_(torch::cat({upsample2_naive(x), skips[1]}, 1));
  x = up4_(torch::cat({upsample2_naive(x), skips[0]}, 1));
  x = up2_(torch::cat({upsample2_naive(x), half}, 1));
  return logits_(x) + kCostLogitScale * upsample2_naive(cost);
}

namespace {

// The dot product of C reference channels with one bilinear sample of C source channels (the taps
// of feature_sampling.h). Vectorised (OpenMP simd reduction) and compiled for AVX2+FMA too.
#if defined(__GNUC__) && defined(__x86_64__)
__attribute__((target_clones("arch=haswell", "default")))
#endif
float dot_with_sample(const float* __restrict r, const float* __restrict nw, const float* __restrict ne,
                      const float* __restrict sw, const float* __restrict se, float w_nw, float w_ne, float w_sw,
                      float w_se, int64_t C) {
  float sum = 0.0f;
#pragma omp simd reduction(+ : sum)
  for (int64_t c = 0; c < C; ++c) sum += r[c] * (nw[c] * w_nw + ne[c] * w_ne + sw[c] * w_sw + se[c] * w_se);
  return sum;
}

// Without autograd on the CPU: every plane, row and pixel sampled straight from channels-last
// unit features (feature_sampling.h), as VarianceCostVolume does; no warped volume is built.
//   unit [B,V,C,h,w] (unit vectors over C); proj [B,V,4,4]; depth_values [B,D]  -> [B,D,h,w]
torch::Tensor cosine_cost_volume_cpu(const torch::Tensor& unit, const torch::Tensor& proj,
                                     const torch::Tensor& depth_values, FeatureWarp warp) {
  const int64_t B = unit.size(0), V = unit.size(1), C = unit.size(2), H = unit.size(3), W = unit.size(4), HW = H * W;
  const int64_t D = depth_values.size(1);
  const auto features = unit.permute({0, 1, 3, 4, 2}).contiguous();  // [B,V,h,w,C]
  const auto depth = depth_values.to(torch::kCPU, torch::kFloat32).contiguous();
  const auto proj_cpu = proj.to(torch::kCPU, torch::kFloat32);
  std::vector<torch::Tensor> rot_xyz, trans;
  for (int64_t v = 1; v < V; ++v) {
    const auto rays = homography_rays(proj_cpu.select(1, v), proj_cpu.select(1, 0), H, W);
    rot_xyz.push_back(rays.rot_xyz.contiguous());
    trans.push_back(rays.trans.reshape({B, 3}).contiguous());
  }
  auto cost = torch::empty({B, D, H, W}, features.options());
  const float* fea = features.data_ptr<float>();
  const float* z_p = depth.data_ptr<float>();
  float* out_p = cost.data_ptr<float>();
  const detail::HomographySampler sampler(H, W, C, warp);
  const float sources = static_cast<float>(V - 1);
  at::parallel_for(0, B * D * H, 4, [&](int64_t task_begin, int64_t task_end) {
    for (int64_t task = task_begin; task < task_end; ++task) {
      const int64_t b = task / (D * H), d = (task / H) % D, y = task % H;
      const float z = z_p[b * D + d];
      float* out = out_p + ((b * D + d) * H + y) * W;
      std::fill_n(out, W, 0.0f);
      const float* ref_row = fea + (b * V * HW + y * W) * C;
      for (int64_t v = 1; v < V; ++v) {
        const float* src = fea + (b * V + v) * HW * C;
        const float* rx = rot_xyz[v - 1].data_ptr<float>() + b * 3 * HW + y * W;
        const float* ry = rx + HW;
        const float* rz = ry + HW;
        const float* t = trans[v - 1].data_ptr<float>() + b * 3;
        detail::FeatureTaps taps;
        for (int64_t x = 0; x < W; ++x) {
          if (!sampler.taps(src, rx[x] * z + t[0], ry[x] * z + t[1], rz[x] * z + t[2], taps)) continue;
          out[x] += dot_with_sample(ref_row + x * C, taps.nw, taps.ne, taps.sw, taps.se, taps.w_nw, taps.w_ne,
                                    taps.w_sw, taps.w_se, C);
        }
      }
      for (int64_t x = 0; x < W; ++x) out[x] /= sources;
    }
  });
  return cost;
}

}  // namespace

torch::Tensor cosine_cost_volume(const torch::Tensor& features, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, FeatureWarp warp) {
  TORCH_CHECK(features.dim() == 5 && features.size(1) >= 2, "features must be [B,V,C,h,w] with V >= 2, got ",
              features.sizes());
  TORCH_CHECK(depth_values.dim() == 2, "depth_values must be [B,D], got ", depth_values.sizes());
  const int64_t V = features.size(1), C = features.size(2), D = depth_values.size(1);
  const auto unit = F::normalize(features, F::NormalizeFuncOptions().dim(2).eps(1e-6));
  if (!torch::GradMode::is_enabled() && unit.device().is_cpu() && unit.scalar_type() == torch::kFloat32) {
    return cosine_cost_volume_cpu(unit, proj, depth_values, warp);
  }
  const auto reference = unit.select(1, 0).unsqueeze(2);  // [B,C,1,h,w]
  const auto ref_proj = proj.select(1, 0);
  // Slabs of planes keep the warped source at ~32 MiB at a time (8 M floats).
  const int64_t plane_floats = features.size(0) * C * features.size(3) * features.size(4);
  const int64_t slab = std::max<int64_t>(1, (int64_t{8} << 20) / std::max<int64_t>(1, plane_floats));
  std::vector<torch::Tensor> slabs;
  for (int64_t begin = 0; begin < D; begin += slab) {
    const auto planes = depth_values.slice(1, begin, std::min(D, begin + slab));
    torch::Tensor cost;
    for (int64_t v = 1; v < V; ++v) {
      const auto warped = homography_warp(unit.select(1, v), proj.select(1, v), ref_proj, planes, warp);
      const auto similarity = (warped * reference).sum(1);  // [B,d,h,w]
      cost = cost.defined() ? cost + similarity : similarity;
    }
    slabs.push_back(cost);
  }
  return torch::cat(slabs, 1) / static_cast<double>(V - 1);
}

double sweep_net_forward_flops(int H, int W, int D, int V) {
  const double half = static_cast<double>(H / 2) * (W / 2), quarter = half / 4;
  const double features = 25 * 3 * 16 * half + 9 * 16 * 16 * half + 25 * 16 * 32 * quarter +
                          9 * 32 * 32 * quarter + 9 * 32 * 16 * quarter;
  const int* c = kEncoderChannels;
  double decoder = 9.0 * (D + 32) * c[0] * quarter, pixels = quarter;
  for (int s = 1; s < 4; ++s) {
    pixels /= 4;
    decoder += 9 * (c[s - 1] * c[s] + c[s] * c[s]) * pixels;
  }
  decoder += 9 * (c[3] + c[2]) * c[2] * quarter / 16 + 9 * (c[2] + c[1]) * c[1] * quarter / 4 +
             9 * (c[1] + c[0]) * kQuarterDecoderChannels * quarter +
             9 * (kQuarterDecoderChannels + 16) * kHalfDecoderChannels * half + kHalfDecoderChannels * D * half;
  return 2.0 * (V * features + decoder);
}

}  // namespace umvs
