#include "unsup_mvs/core/fast_mvsnet.h"

#include <ATen/Context.h>
#include <ATen/Parallel.h>
#include <ATen/ops/constant_pad_nd.h>
#include <ATen/ops/mkldnn_convolution.h>
#include <torch/version.h>
#include <torch/nn/modules/batchnorm.h>
#include <torch/nn/modules/conv.h>
#include <torch/utils.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <type_traits>
#include <vector>

#include "feature_sampling.h"
#include "unsup_mvs/core/fine_pass.h"
#include "unsup_mvs/core/geometry.h"

namespace umvs {

namespace {

using Clock = std::chrono::steady_clock;

double lap(Clock::time_point& t0) {
  const auto t1 = Clock::now();
  const double s = std::chrono::duration<double>(t1 - t0).count();
  t0 = t1;
  return s;
}

// Eval-mode BatchNorm as y = x * scale + shift per channel (float64, rounded once when folded).
struct ScaleShift {
  torch::Tensor scale, shift;  // [C] float64
};
ScaleShift batch_norm_affine(const torch::nn::BatchNorm3dImpl& bn) {
  const auto f64 = [](const torch::Tensor& t) { return t.detach().to(torch::kCPU, torch::kFloat64); };
  auto scale = f64(bn.weight) / (f64(bn.running_var) + bn.options.eps()).sqrt();
  return {scale, f64(bn.bias) - f64(bn.running_mean) * scale};
}

// A 3-D convolution (kernel 3, padding 1) with its BatchNorm folded in.
struct FoldedConv {
  torch::Tensor weight;  // [Cout,Cin,3,3,3]
  torch::Tensor bias;    // [Cout]
  int64_t stride = 1;
};

// A stride-2 transposed convolution (kernel 3, padding 1, output padding 1) with its BatchNorm
// folded in, as 8 convolutions, one per output parity (pd, ph, pw). Along one dimension, output
// 2m only sees input m through tap 1 and output 2m+1 sees input m through tap 2 and input m+1
// through tap 0: a kernel of 1 or 2 taps over the input padded by one zero at the end.
struct SubPixelDeconv {
  std::array<torch::Tensor, 8> weight;  // [Cout,Cin,kd,kh,kw], k = 1 (even) or 2 (odd)
  torch::Tensor bias;                   // [Cout]
};

int64_t first(const torch::ExpandingArray<3>& a) { return (*a)[0]; }
int64_t first(const torch::nn::detail::conv_padding_t<3>& padding) {
  // The padding variant is a c10::variant up to LibTorch 2.0 and a std::variant from 2.1 on.
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 1)
  return first(std::get<torch::ExpandingArray<3>>(padding));
#else
  return first(c10::get<torch::ExpandingArray<3>>(padding));
#endif
}

FoldedConv fold(const torch::nn::Conv3dImpl& conv, const torch::nn::BatchNorm3dImpl* bn) {
  TORCH_CHECK(first(conv.options.kernel_size()) == 3 &&
                  first(conv.options.padding()) == 1,
              "fast MVSNet: unexpected 3-D convolution shape");
  FoldedConv out;
  out.stride = first(conv.options.stride());
  auto weight = conv.weight.detach().to(torch::kCPU, torch::kFloat64);
  auto bias = conv.bias.defined() ? conv.bias.detach().to(torch::kCPU, torch::kFloat64)
                                  : torch::zeros({weight.size(0)}, torch::kFloat64);
  if (bn) {
    const auto a = batch_norm_affine(*bn);
    weight = weight * a.scale.view({-1, 1, 1, 1, 1});
    bias = bias * a.scale + a.shift;
  }
  out.weight = weight.to(torch::kFloat32).contiguous();
  out.bias = bias.to(torch::kFloat32).contiguous();
  return out;
}

SubPixelDeconv fold(const torch::nn::ConvTranspose3dImpl& deconv, const torch::nn::BatchNorm3dImpl& bn) {
  const auto& o = deconv.options;
  TORCH_CHECK(first(o.kernel_size()) == 3 && first(o.stride()) == 2 && first(o.padding()) == 1 &&
                  first(o.output_padding()) == 1 && !deconv.bias.defined(),
              "fast MVSNet: unexpected transposed 3-D convolution shape");
  const auto a = batch_norm_affine(bn);
  // [Cin,Cout,3,3,3] -> [Cout,Cin,3,3,3] with the BatchNorm scale on Cout.
  auto weight = (deconv.weight.detach().to(torch::kCPU, torch::kFloat64) * a.scale.view({1, -1, 1, 1, 1})).transpose(0, 1);
  const std::array<torch::Tensor, 2> taps = {torch::tensor({1}, torch::kLong), torch::tensor({2, 0}, torch::kLong)};
  SubPixelDeconv out;
  for (int k = 0; k < 8; ++k) {
    out.weight[k] = weight.index_select(2, taps[(k >> 2) & 1])
                        .index_select(3, taps[(k >> 1) & 1])
                        .index_select(4, taps[k & 1])
                        .to(torch::kFloat32)
                        .contiguous();
  }
  out.bias = a.shift.to(torch::kFloat32).contiguous();
  return out;
}

torch::Tensor onednn_conv3d(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                            int64_t stride, at::IntArrayRef padding) {
  return at::mkldnn_convolution(x, weight, bias, padding, {stride, stride, stride}, {1, 1, 1}, 1);
}

torch::Tensor conv_relu(const torch::Tensor& x, const FoldedConv& layer) {
  return onednn_conv3d(x, layer.weight, layer.bias, layer.stride, {1, 1, 1}).relu_();
}

// skip + relu(transposed convolution of x), written into `skip` (the U-Net's skip connection,
// not needed afterwards): no output buffer of the full size is allocated.
torch::Tensor deconv_relu_add_into(const torch::Tensor& x, const SubPixelDeconv& layer, torch::Tensor skip) {
  const int64_t D = x.size(2), H = x.size(3), W = x.size(4);
  TORCH_CHECK(skip.size(1) == layer.bias.size(0) && skip.size(2) == 2 * D && skip.size(3) == 2 * H && skip.size(4) == 2 * W,
              "fast MVSNet: skip connection of the wrong shape");
  auto padded = at::constant_pad_nd(x, {0, 1, 0, 1, 0, 1}, 0);
  for (int k = 0; k < 8; ++k) {
    // A 1-tap dimension gives one output too many over the padded input: cut it.
    auto y = onednn_conv3d(padded, layer.weight[k], layer.bias, 1, {0, 0, 0});
    skip.slice(2, (k >> 2) & 1, 2 * D, 2)
        .slice(3, (k >> 1) & 1, 2 * H, 2)
        .slice(4, k & 1, 2 * W, 2)
        .add_(y.slice(2, 0, D).slice(3, 0, H).slice(4, 0, W).relu_());
  }
  return skip;
}

// out[x] += w0 in[x-1] + w1 in[x] + w2 in[x+1] over one row, zero beyond its ends.
// Compiled for AVX2+FMA too, picked at run time (the build targets baseline x86-64).
#if defined(__GNUC__) && defined(__x86_64__)
__attribute__((target_clones("arch=haswell", "default")))
#endif
void row_taps3(float* out, const float* in, int64_t width, float w0, float w1, float w2) {
  if (width == 1) {
    out[0] += w1 * in[0];
    return;
  }
  out[0] += w1 * in[0] + w2 * in[1];
  for (int64_t x = 1; x < width - 1; ++x) out[x] += w0 * in[x - 1] + w1 * in[x] + w2 * in[x + 1];
  out[width - 1] += w0 * in[width - 2] + w1 * in[width - 1];
}

// A 3-D convolution with a single output channel (kernel 3, padding 1, stride 1) as row
// AXPYs: oneDNN runs single-output-channel convolutions at a few GFLOP/s (the U-Net's last layer).
//   x [B,C,D,H,W]; weight [1,C,3,3,3]; bias [1]  -> [B,D,H,W]
torch::Tensor single_output_conv3d(const torch::Tensor& input, const torch::Tensor& weight, const torch::Tensor& bias) {
  const auto x = input.contiguous();
  const int64_t B = x.size(0), C = x.size(1), D = x.size(2), H = x.size(3), W = x.size(4);
  auto out = torch::empty({B, D, H, W}, x.options());
  const float* in_p = x.data_ptr<float>();
  const float* w_p = weight.data_ptr<float>();
  const float b0 = bias.item<float>();
  float* out_p = out.data_ptr<float>();
  at::parallel_for(0, B * D * H, 16, [&](int64_t begin, int64_t end) {
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / (D * H), d = (row / H) % D, y = row % H;
      float* o = out_p + row * W;
      std::fill_n(o, W, b0);
      for (int64_t c = 0; c < C; ++c) {
        for (int64_t kd = 0; kd < 3; ++kd) {
          const int64_t dd = d + kd - 1;
          if (dd < 0 || dd >= D) continue;
          for (int64_t kh = 0; kh < 3; ++kh) {
            const int64_t yy = y + kh - 1;
            if (yy < 0 || yy >= H) continue;
            const float* w = w_p + ((c * 3 + kd) * 3 + kh) * 3;
            row_taps3(o, in_p + (((b * C + c) * D + dd) * H + yy) * W, W, w[0], w[1], w[2]);
          }
        }
      }
    }
  });
  return out;
}

// One bilinear sample of C channels added to the running sum and sum of squares (the taps are
// C contiguous floats each). Compiled for AVX2+FMA too, picked at run time.
#if defined(__GNUC__) && defined(__x86_64__)
__attribute__((target_clones("arch=haswell", "default")))
#endif
void accumulate_sample(float* __restrict sum, float* __restrict sq_sum, const float* __restrict p_nw,
                       const float* __restrict p_ne, const float* __restrict p_sw, const float* __restrict p_se,
                       float nw, float ne, float sw, float se, int64_t C) {
  for (int64_t c = 0; c < C; ++c) {
    const float value = p_nw[c] * nw + p_ne[c] * ne + p_sw[c] * sw + p_se[c] * se;
    sum[c] += value;
    sq_sum[c] += value * value;
  }
}

}  // namespace

struct FastMvsNet::FoldedUNet {
  std::array<FoldedConv, 7> conv;       // conv0 .. conv6 of CostRegNet
  std::array<SubPixelDeconv, 3> up;     // conv7, conv9, conv11
  FoldedConv prob;

  explicit FoldedUNet(CostRegNetImpl& net) {
    std::map<std::string, std::shared_ptr<torch::nn::Module>> modules;
    for (const auto& item : net.named_modules("", /*include_self=*/false)) modules[item.key()] = item.value();
    using torch::nn::BatchNorm3dImpl, torch::nn::Conv3dImpl, torch::nn::ConvTranspose3dImpl;
    const auto get = [&](const std::string& name, auto* type) -> decltype(type) {
      auto* module = modules.count(name) ? modules.at(name)->as<std::remove_pointer_t<decltype(type)>>() : nullptr;
      TORCH_CHECK(module, "fast MVSNet: the 3-D U-Net has no module ", name, " of the expected type");
      return module;
    };
    for (int i = 0; i < 7; ++i) {
      const std::string n = "conv" + std::to_string(i);
      conv[i] = fold(*get(n + ".conv", (Conv3dImpl*)nullptr), get(n + ".bn", (BatchNorm3dImpl*)nullptr));
    }
    const char* up_names[3] = {"conv7", "conv9", "conv11"};
    for (int i = 0; i < 3; ++i) {
      const std::string n = up_names[i];
      up[i] = fold(*get(n + ".0", (ConvTranspose3dImpl*)nullptr), *get(n + ".1", (BatchNorm3dImpl*)nullptr));
    }
    prob = fold(*get("prob", (Conv3dImpl*)nullptr), nullptr);
  }

  // CostRegNetImpl::forward with BatchNorm folded, on the cost volume built slab by slab: each
  // slab of planes (with one plane either side) goes through conv0 as soon as it is built, so the
  // 32-channel volume never exists whole.  -> logits [B,D,h,w]; *volume_seconds: time spent
  // building the volume.
  torch::Tensor forward(const VarianceCostVolume& volume, int64_t slab_floats, double* volume_seconds) const {
    const int64_t D = volume.num_planes();
    const int64_t slab = std::clamp<int64_t>(slab_floats / volume.plane_elements(), 1, D);
    torch::Tensor c0;
    *volume_seconds = 0;
    for (int64_t begin = 0; begin < D; begin += slab) {
      const int64_t end = std::min(D, begin + slab);
      auto t0 = Clock::now();
      auto planes = volume.planes(begin - 1, end + 1);
      *volume_seconds += lap(t0);
      // The halo planes (zeros outside the volume) replace the padding along D.
      auto y = onednn_conv3d(planes, conv[0].weight, conv[0].bias, 1, {0, 1, 1});
      if (!c0.defined()) c0 = torch::empty({y.size(0), y.size(1), D, y.size(3), y.size(4)}, y.options());
      c0.slice(2, begin, end).copy_(y);
    }
    return after_conv0(std::move(c0));
  }

  // The same on a whole volume [B,32,D,h,w] at once (small volumes: the fine pass).
  torch::Tensor forward(const torch::Tensor& volume) const {
    return after_conv0(onednn_conv3d(volume.contiguous(), conv[0].weight, conv[0].bias, 1, {1, 1, 1}));
  }

 private:
  // conv0's output (before its ReLU)  -> logits [B,D,h,w]
  torch::Tensor after_conv0(torch::Tensor c0) const {
    c0.relu_();
    auto c2 = conv_relu(conv_relu(c0, conv[1]), conv[2]);
    auto c4 = conv_relu(conv_relu(c2, conv[3]), conv[4]);
    auto x = conv_relu(conv_relu(c4, conv[5]), conv[6]);
    x = deconv_relu_add_into(x, up[0], std::move(c4));
    x = deconv_relu_add_into(x, up[1], std::move(c2));
    x = deconv_relu_add_into(x, up[2], std::move(c0));
    return single_output_conv3d(x, prob.weight, prob.bias);
  }
};

FastMvsNet::FastMvsNet(MvsNet model, int64_t slab_floats) : model_(std::move(model)), slab_floats_(slab_floats) {
  TORCH_CHECK(slab_floats > 0, "FastMvsNet: slab_floats must be positive");
  model_->eval();
  // A sweep2d network has no 3-D U-Net: its forward() is 2-D convolutions, already on oneDNN.
  if (at::hasMKLDNN() && model_->cost_regularization) unet_ = std::make_unique<FoldedUNet>(*model_->cost_regularization);
}

FastMvsNet::~FastMvsNet() = default;

bool FastMvsNet::accelerates(const torch::Device& device) { return device.is_cpu() && at::hasMKLDNN(); }

torch::Tensor FastMvsNet::plane_probabilities(const torch::Tensor& features, const torch::Tensor& proj,
                                              const torch::Tensor& depth_values, MvsStageTimes& t) {
  auto t0 = Clock::now();
  const VarianceCostVolume volume(features, proj, depth_values, model_->config().feature_warp);
  t.cost_volume += lap(t0);
  double volume_seconds = 0;  // the slabs' share of the U-Net's call
  auto prob = torch::softmax(unet_->forward(volume, slab_floats_, &volume_seconds), 1);
  t.cost_volume += volume_seconds;
  t.regularization += lap(t0) - volume_seconds;
  return prob;
}

MvsOutput FastMvsNet::forward(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values,
                              bool keep_prob_volume, MvsStageTimes* times) {
  torch::NoGradGuard no_grad;
  if (model_->config().network == NetworkKind::kSweep2d) {
    MvsNetImpl::check_inputs(images, proj, depth_values);
    return model_->forward_sweep2d(images, proj, depth_values, keep_prob_volume, times);
  }
  if (!unet_ || !accelerates(images.device()) || images.scalar_type() != torch::kFloat32) {
    return model_->forward(images, proj, depth_values, keep_prob_volume);
  }
  MvsNetImpl::check_inputs(images, proj, depth_values);
  MvsStageTimes t;
  auto t0 = Clock::now();
  auto features = model_->view_features(images);
  t.features = lap(t0);
  auto prob = plane_probabilities(features, proj, depth_values, t);
  features = torch::Tensor();
  t0 = Clock::now();
  MvsOutput out;
  out.depth_init = expected_depth(prob, depth_values);
  out.confidence = photometric_confidence(prob);
  if (keep_prob_volume) out.prob_volume = prob;
  t.regression = lap(t0);
  out.depth = model_->refine_network ? model_->refine_depth(images, out.depth_init, depth_values) : out.depth_init;
  t.refinement = lap(t0);
  if (times) *times = t;
  return out;
}

MvsOutput FastMvsNet::forward_coarse_to_fine(const torch::Tensor& images, const torch::Tensor& proj,
                                             const torch::Tensor& depth_values, const FinePassConfig& fine,
                                             const torch::Tensor& proj_fine, MvsStageTimes* times) {
  torch::NoGradGuard no_grad;
  TORCH_CHECK(model_->config().network == NetworkKind::kMvsNet, "a fine pass runs MVSNet twice; this is a ",
              to_string(model_->config().network), " network (its map is at 1/2 already)");
  check_coarse_to_fine_inputs(images, proj, depth_values, fine, proj_fine);
  const bool fast = unet_ && accelerates(images.device()) && images.scalar_type() == torch::kFloat32;
  if (!fast) return coarse_to_fine_forward(*model_, images, proj, depth_values, fine, proj_fine);
  const FeatureWarp warp = model_->config().feature_warp;
  MvsStageTimes t;
  auto t0 = Clock::now();
  auto features = model_->view_features(images);  // [B,V,32,h,w]
  // The first pass's views and projections: the input's, or at half its size.
  auto coarse_features = features;
  auto coarse_proj = proj;
  if (fine.first_pass_downscale == 2) {
    const auto [half_images, half_proj] = half_size_views(images, proj);
    coarse_features = model_->view_features(half_images);
    coarse_proj = half_proj;
  }
  t.features = lap(t0);
  auto coarse_prob = plane_probabilities(coarse_features, coarse_proj, depth_values, t);
  coarse_features = torch::Tensor();
  t0 = Clock::now();
  MvsOutput out;
  out.depth_init = expected_depth(coarse_prob, depth_values);
  FineGrid grid = to_fine_grid(out.depth_init, photometric_confidence(coarse_prob), features, fine);
  coarse_prob = torch::Tensor();
  features = torch::Tensor();
  const auto hypotheses = fine_pass_hypotheses(grid.depth, depth_values, model_->config().depth_sampling, fine);
  t.regression = lap(t0);
  const auto fine_volume = VarianceCostVolume(grid.features, proj_fine, hypotheses, warp).planes(0, fine.planes);
  grid.features = torch::Tensor();
  t.fine_cost_volume = lap(t0);
  const auto fine_prob = torch::softmax(unet_->forward(fine_volume), 1);
  t.fine_regularization = lap(t0);
  out.depth = (fine_prob * hypotheses).sum(1);
  out.confidence = grid.confidence;
  t.regression += lap(t0);
  t.cost_volume += t.fine_cost_volume;
  t.regularization += t.fine_regularization;
  if (times) *times = t;
  return out;
}

VarianceCostVolume::VarianceCostVolume(const torch::Tensor& features, const torch::Tensor& proj,
                                       const torch::Tensor& depth_values, FeatureWarp warp)
    : warp_(warp) {
  TORCH_CHECK(features.dim() == 5 && features.device().is_cpu() && features.scalar_type() == torch::kFloat32,
              "variance_cost_volume: features must be float32 [B,V,C,h,w] on the CPU, got ", features.sizes());
  B_ = features.size(0), V_ = features.size(1), C_ = features.size(2), H_ = features.size(3), W_ = features.size(4);
  TORCH_CHECK(proj.dim() == 4 && proj.size(0) == B_ && proj.size(1) == V_, "variance_cost_volume: proj must be [B,V,4,4]");
  // Planes [B,D], or D hypotheses per pixel [B,D,h,w] (a fine pass).
  per_pixel_ = depth_values.dim() == 4;
  TORCH_CHECK((depth_values.dim() == 2 || (per_pixel_ && depth_values.size(2) == H_ && depth_values.size(3) == W_)) &&
                  depth_values.size(0) == B_,
              "variance_cost_volume: depth_values must be [B,D] or [B,D,h,w], got ", depth_values.sizes());
  D_ = depth_values.size(1);
  torch::NoGradGuard no_grad;
  // Channels last, so that one bilinear tap reads C contiguous floats.
  features_ = features.permute({0, 1, 3, 4, 2}).contiguous();  // [B,V,h,w,C]
  depth_ = depth_values.to(torch::kCPU, torch::kFloat32).contiguous();
  const auto proj_cpu = proj.to(torch::kCPU, torch::kFloat32);
  for (int64_t v = 1; v < V_; ++v) {
    auto rays = homography_rays(proj_cpu.select(1, v), proj_cpu.select(1, 0), H_, W_);
    rot_xyz_.push_back(rays.rot_xyz.contiguous());
    trans_.push_back(rays.trans.reshape({B_, 3}).contiguous());
  }
}

torch::Tensor VarianceCostVolume::planes(int64_t begin, int64_t end) const {
  TORCH_CHECK(begin < end, "VarianceCostVolume::planes: empty range");
  const int64_t B = B_, V = V_, C = C_, H = H_, W = W_, D = D_, HW = H * W, P = end - begin;
  auto volume = torch::empty({B, C, P, H, W}, features_.options());
  const float* fea_p = features_.data_ptr<float>();
  const float* depth_p = depth_.data_ptr<float>();
  float* volume_p = volume.data_ptr<float>();
  const detail::HomographySampler sampler(H, W, C, warp_);
  const float num_views = static_cast<float>(V);

  // One task per (batch, plane, row); each keeps its row's sums in [w,C] buffers.
  at::parallel_for(0, B * P * H, 4, [&](int64_t task_begin, int64_t task_end) {
    std::vector<float> sum(W * C), sq_sum(W * C);
    for (int64_t task = task_begin; task < task_end; ++task) {
      const int64_t b = task / (P * H), p = (task / H) % P, y = task % H, d = begin + p;
      if (d < 0 || d >= D) {  // outside the volume: zero padding for the next convolution
        for (int64_t c = 0; c < C; ++c) std::fill_n(volume_p + (((b * C + c) * P + p) * H + y) * W, W, 0.0f);
        continue;
      }
      // The row's hypothesis d: one depth for the plane, or one per pixel.
      const float* z_row = per_pixel_ ? depth_p + ((b * D + d) * H + y) * W : nullptr;
      const float z_plane = per_pixel_ ? 0.0f : depth_p[b * D + d];
      const float* ref_row = fea_p + (b * V * HW + y * W) * C;
      for (int64_t i = 0; i < W * C; ++i) {
        sum[i] = ref_row[i];
        sq_sum[i] = ref_row[i] * ref_row[i];
      }
      for (int64_t v = 1; v < V; ++v) {
        const float* src = fea_p + (b * V + v) * HW * C;
        const float* rx = rot_xyz_[v - 1].data_ptr<float>() + b * 3 * HW + y * W;
        const float* ry = rx + HW;
        const float* rz = ry + HW;
        const float* t = trans_[v - 1].data_ptr<float>() + b * 3;
        detail::FeatureTaps taps;
        for (int64_t x = 0; x < W; ++x) {
          const float z = z_row ? z_row[x] : z_plane;
          const float px = rx[x] * z + t[0], py = ry[x] * z + t[1], pz = rz[x] * z + t[2];
          if (!sampler.taps(src, px, py, pz, taps)) continue;  // all taps outside: adds zeros
          accumulate_sample(sum.data() + x * C, sq_sum.data() + x * C, taps.nw, taps.ne, taps.sw, taps.se, taps.w_nw,
                            taps.w_ne, taps.w_sw, taps.w_se, C);
        }
      }
      for (int64_t c = 0; c < C; ++c) {
        float* out = volume_p + (((b * C + c) * P + p) * H + y) * W;
        for (int64_t x = 0; x < W; ++x) {
          const float mean = sum[x * C + c] / num_views;
          out[x] = sq_sum[x * C + c] / num_views - mean * mean;
        }
      }
    }
  });
  return volume;
}

torch::Tensor variance_cost_volume(const torch::Tensor& features, const torch::Tensor& proj,
                                   const torch::Tensor& depth_values, FeatureWarp warp) {
  const VarianceCostVolume volume(features, proj, depth_values, warp);
  return volume.planes(0, volume.num_planes());
}

}  // namespace umvs
