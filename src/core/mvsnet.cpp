#include "unsup_mvs/core/mvsnet.h"

#include <torch/torch.h>

#include <chrono>
#include <sstream>
#include <stdexcept>

namespace umvs {

namespace nn = torch::nn;
namespace F = torch::nn::functional;

const char* to_string(InputNormalization n) {
  switch (n) {
    case InputNormalization::kNone: return "none";
    case InputNormalization::kPerImageChannel: return "per_image_channel";
  }
  return "?";
}

InputNormalization input_normalization_from_string(const std::string& name) {
  if (name == "none") return InputNormalization::kNone;
  if (name == "per_image_channel") return InputNormalization::kPerImageChannel;
  throw std::invalid_argument("input normalisation must be none or per_image_channel, got '" + name + "'");
}

torch::Tensor normalize_input_images(const torch::Tensor& images, InputNormalization normalization) {
  if (normalization == InputNormalization::kNone) return images;
  // The variance floor keeps a flat (or black) image finite: it maps to zeros.
  auto mean = images.mean({-2, -1}, /*keepdim=*/true);
  auto var = images.var({-2, -1}, /*unbiased=*/false, /*keepdim=*/true);
  return (images - mean) * torch::rsqrt(var + 1e-6);
}

const char* to_string(NetworkKind n) {
  switch (n) {
    case NetworkKind::kMvsNet: return "mvsnet";
    case NetworkKind::kSweep2d: return "sweep2d";
  }
  return "?";
}

NetworkKind network_kind_from_string(const std::string& name) {
  if (name == "mvsnet") return NetworkKind::kMvsNet;
  if (name == "sweep2d") return NetworkKind::kSweep2d;
  throw std::invalid_argument("network must be mvsnet or sweep2d, got '" + name + "'");
}

void MvsNetConfig::validate() const {
  if (num_depth < 8 || num_depth % 8 != 0) {
    throw std::invalid_argument("num_depth must be a positive multiple of 8 (the 3-D U-Net halves it "
                                "three times), got " + std::to_string(num_depth));
  }
  if (num_views < 2) throw std::invalid_argument("num_views must be >= 2, got " + std::to_string(num_views));
  if (network == NetworkKind::kSweep2d && refine) {
    throw std::invalid_argument("refine: the sweep2d network has no refinement network (its map is at 1/2 already)");
  }
}

std::string MvsNetConfig::architecture_mismatch(const MvsNetConfig& other) const {
  if (network != other.network) {
    return std::string("network: ") + umvs::to_string(network) + " here, " + umvs::to_string(other.network) +
           " in the other model";
  }
  if (planes_fixed_by_weights() && num_depth != other.num_depth) {
    return "planes (fixed by a sweep2d network's weights): " + std::to_string(num_depth) + " here, " +
           std::to_string(other.num_depth) + " in the other model";
  }
  if (refine != other.refine) {
    return std::string("refinement network: ") + (refine ? "present" : "absent") + " here, " +
           (other.refine ? "present" : "absent") + " in the other model";
  }
  return "";
}

std::string MvsNetConfig::to_string() const {
  std::ostringstream os;
  os << "network=" << umvs::to_string(network) << " num_depth=" << num_depth << " depth_sampling=" << umvs::to_string(depth_sampling)
     << " refine=" << (refine ? "true" : "false") << " num_views=" << num_views
     << " input_normalization=" << umvs::to_string(input_normalization)
     << " feature_warp=" << umvs::to_string(feature_warp);
  return os.str();
}

ConvBnReLUImpl::ConvBnReLUImpl(int in, int out, int kernel, int stride, int pad) {
  conv = register_module("conv", nn::Conv2d(nn::Conv2dOptions(in, out, kernel).stride(stride).padding(pad).bias(false)));
  bn = register_module("bn", nn::BatchNorm2d(out));
}
torch::Tensor ConvBnReLUImpl::forward(const torch::Tensor& x) { return torch::relu(bn(conv(x))); }

ConvBnReLU3DImpl::ConvBnReLU3DImpl(int in, int out, int kernel, int stride, int pad) {
  conv = register_module("conv", nn::Conv3d(nn::Conv3dOptions(in, out, kernel).stride(stride).padding(pad).bias(false)));
  bn = register_module("bn", nn::BatchNorm3d(out));
}
torch::Tensor ConvBnReLU3DImpl::forward(const torch::Tensor& x) { return torch::relu(bn(conv(x))); }

FeatureNetImpl::FeatureNetImpl() {
  // (in, out, kernel, stride, pad) of conv0..conv6: two 5x5 stride-2 layers give 1/4 resolution.
  const int spec[7][5] = {{3, 8, 3, 1, 1},   {8, 8, 3, 1, 1},   {8, 16, 5, 2, 2}, {16, 16, 3, 1, 1},
                          {16, 16, 3, 1, 1}, {16, 32, 5, 2, 2}, {32, 32, 3, 1, 1}};
  for (int i = 0; i < 7; ++i) {
    const auto* s = spec[i];
    layers_.push_back(register_module("conv" + std::to_string(i), ConvBnReLU(s[0], s[1], s[2], s[3], s[4])));
  }
  feature_ = register_module("feature", nn::Conv2d(nn::Conv2dOptions(32, kChannels, 3).padding(1)));
}

torch::Tensor FeatureNetImpl::forward(const torch::Tensor& image) {
  auto x = image;
  for (auto& layer : layers_) x = layer(x);
  return feature_(x);
}

namespace {
nn::Sequential deconv_bn_relu(int in, int out) {
  return nn::Sequential(
      nn::ConvTranspose3d(nn::ConvTranspose3dOptions(in, out, 3).stride(2).padding(1).output_padding(1).bias(false)),
      nn::BatchNorm3d(out), nn::ReLU());
}
}  // namespace

CostRegNetImpl::CostRegNetImpl() {
  conv0_ = register_module("conv0", ConvBnReLU3D(32, 8));
  conv1_ = register_module("conv1", ConvBnReLU3D(8, 16, 3, 2, 1));
  conv2_ = register_module("conv2", ConvBnReLU3D(16, 16));
  conv3_ = register_module("conv3", ConvBnReLU3D(16, 32, 3, 2, 1));
  conv4_ = register_module("conv4", ConvBnReLU3D(32, 32));
  conv5_ = register_module("conv5", ConvBnReLU3D(32, 64, 3, 2, 1));
  conv6_ = register_module("conv6", ConvBnReLU3D(64, 64));
  conv7_ = register_module("conv7", deconv_bn_relu(64, 32));
  conv9_ = register_module("conv9", deconv_bn_relu(32, 16));
  conv11_ = register_module("conv11", deconv_bn_relu(16, 8));
  prob_ = register_module("prob", nn::Conv3d(nn::Conv3dOptions(8, 1, 3).padding(1)));
}

torch::Tensor CostRegNetImpl::forward(const torch::Tensor& cost) {
  auto c0 = conv0_(cost);
  auto c2 = conv2_(conv1_(c0));
  auto c4 = conv4_(conv3_(c2));
  auto x = conv6_(conv5_(c4));
  x = c4 + conv7_->forward(x);
  x = c2 + conv9_->forward(x);
  x = c0 + conv11_->forward(x);
  return prob_(x).squeeze(1);
}

RefineNetImpl::RefineNetImpl() {
  conv1_ = register_module("conv1", ConvBnReLU(4, 32));
  conv2_ = register_module("conv2", ConvBnReLU(32, 32));
  conv3_ = register_module("conv3", ConvBnReLU(32, 32));
  res_ = register_module("res", nn::Conv2d(nn::Conv2dOptions(32, 1, 3).padding(1)));
}

torch::Tensor RefineNetImpl::forward(const torch::Tensor& image, const torch::Tensor& depth,
                                     const torch::Tensor& depth_min, const torch::Tensor& depth_max) {
  auto lo = depth_min.view({-1, 1, 1}), range = (depth_max - depth_min).view({-1, 1, 1});
  auto normalised = ((depth - lo) / range).unsqueeze(1);
  auto residual = res_(conv3_(conv2_(conv1_(torch::cat({image, normalised}, 1))))).squeeze(1);
  return depth + residual * range;
}

torch::Tensor expected_depth(const torch::Tensor& prob, const torch::Tensor& depth_values) {
  const int64_t B = prob.size(0), D = prob.size(1);
  return (prob * depth_values.view({B, D, 1, 1})).sum(1);
}

torch::Tensor photometric_confidence(const torch::Tensor& prob) {
  const int64_t D = prob.size(1);
  auto index_values = torch::arange(D, prob.options()).view({1, D, 1, 1});
  auto index = (prob * index_values).sum(1).to(torch::kLong);  // truncation, as the reference
  // One zero plane before and two after, so that planes i-1 .. i+2 are padded[i .. i+3].
  auto padded = F::pad(prob, F::PadFuncOptions({0, 0, 0, 0, 1, 2}));
  index = index.clamp(0, D - 1).unsqueeze(1);
  auto conf = padded.gather(1, index) + padded.gather(1, index + 1) + padded.gather(1, index + 2) +
              padded.gather(1, index + 3);
  return conf.squeeze(1);
}

MvsNetImpl::MvsNetImpl(const MvsNetConfig& config) : config_(config) {
  config_.validate();
  if (config_.network == NetworkKind::kSweep2d) {
    sweep_features = register_module("sweep_features", SweepFeatureNet());
    cost_decoder = register_module("cost_decoder", CostDecoder2D(config_.num_depth));
    return;
  }
  feature = register_module("feature", FeatureNet());
  cost_regularization = register_module("cost_regularization", CostRegNet());
  if (config_.refine) refine_network = register_module("refine_network", RefineNet());
}

void MvsNetImpl::set_num_depth(int d) {
  if (config_.planes_fixed_by_weights() && d != config_.num_depth) {
    throw std::invalid_argument("this sweep2d network was trained for " + std::to_string(config_.num_depth) +
                                " planes (its weights fix the count), asked for " + std::to_string(d));
  }
  config_.num_depth = d;
}

void MvsNetImpl::check_inputs(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values) {
  TORCH_CHECK(images.dim() == 5 && images.size(2) == 3, "images must be [B,V,3,H,W], got ", images.sizes());
  TORCH_CHECK(images.size(3) % 32 == 0 && images.size(4) % 32 == 0,
              "image height and width must be multiples of 32, got ", images.size(3), "x", images.size(4));
  TORCH_CHECK(proj.dim() == 4 && proj.size(1) == images.size(1), "proj must be [B,V,4,4]");
  TORCH_CHECK(depth_values.dim() == 2 && depth_values.size(1) % 8 == 0,
              "depth_values must be [B,D] with D a multiple of 8, got ", depth_values.sizes());
}

torch::Tensor MvsNetImpl::view_features(const torch::Tensor& images) {
  TORCH_CHECK(feature, "view_features: MVSNet's feature net; this is a ", to_string(config_.network), " network");
  const int64_t B = images.size(0), V = images.size(1);
  // Shared feature extractor over all views at once.
  auto features = feature(normalize_input_images(images.flatten(0, 1), config_.input_normalization));  // [B*V,32,h,w]
  return features.view({B, V, features.size(1), features.size(2), features.size(3)});
}

torch::Tensor MvsNetImpl::refine_depth(const torch::Tensor& images, const torch::Tensor& depth_init,
                                       const torch::Tensor& depth_values) {
  TORCH_CHECK(refine_network, "this model has no refinement network");
  auto ref_image = images.select(1, 0);
  auto small = F::interpolate(ref_image, F::InterpolateFuncOptions()
                                             .size(std::vector<int64_t>{depth_init.size(1), depth_init.size(2)})
                                             .mode(torch::kArea));
  return refine_network(small, depth_init, depth_values.select(1, 0), depth_values.select(1, depth_values.size(1) - 1));
}

MvsOutput MvsNetImpl::forward_sweep2d(const torch::Tensor& images, const torch::Tensor& proj,
                                      const torch::Tensor& depth_values, bool keep_prob_volume, MvsStageTimes* times) {
  TORCH_CHECK(sweep_features, "forward_sweep2d: this is a ", to_string(config_.network), " network");
  TORCH_CHECK(depth_values.size(1) == config_.num_depth, "this sweep2d network was trained for ", config_.num_depth,
              " planes (its weights fix the count), got ", depth_values.size(1));
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  const auto lap = [&t0](double MvsStageTimes::*stage, MvsStageTimes* t) {
    const auto t1 = Clock::now();
    if (t) t->*stage = std::chrono::duration<double>(t1 - t0).count();
    t0 = t1;
  };
  const int64_t B = images.size(0), V = images.size(1);
  const auto f = sweep_features(normalize_input_images(images.flatten(0, 1), config_.input_normalization));
  lap(&MvsStageTimes::features, times);
  const auto per_view = [&](const torch::Tensor& t) { return t.view({B, V, t.size(1), t.size(2), t.size(3)}); };
  const auto cost = cosine_cost_volume(per_view(f.matching), proj, depth_values, config_.feature_warp);
  lap(&MvsStageTimes::cost_volume, times);
  const auto logits = cost_decoder(cost, per_view(f.quarter).select(1, 0), per_view(f.half).select(1, 0));
  lap(&MvsStageTimes::regularization, times);
  const auto prob = torch::softmax(logits, 1);
  MvsOutput out;
  out.depth_init = expected_depth(prob, depth_values);
  {
    torch::NoGradGuard no_grad;
    out.confidence = photometric_confidence(prob);
  }
  out.depth = out.depth_init;
  if (keep_prob_volume) out.prob_volume = prob;
  lap(&MvsStageTimes::regression, times);
  return out;
}

MvsOutput MvsNetImpl::forward(const torch::Tensor& images, const torch::Tensor& proj,
                              const torch::Tensor& depth_values, bool keep_prob_volume) {
  check_inputs(images, proj, depth_values);
  if (config_.network == NetworkKind::kSweep2d) return forward_sweep2d(images, proj, depth_values, keep_prob_volume);
  const int64_t V = images.size(1);
  auto features = view_features(images);  // [B,V,32,h,w]
  const int64_t D = depth_values.size(1);

  // Variance cost volume, accumulated view by view so that only a few volumes live at once.
  // Without autograd the sums are updated in place (as MVSNet_pytorch does at inference).
  const bool in_place = !torch::GradMode::is_enabled();
  auto ref_proj = proj.select(1, 0);
  auto volume_sum = features.select(1, 0).unsqueeze(2).repeat({1, 1, D, 1, 1});
  auto volume_sq_sum = volume_sum.pow(2);
  for (int64_t v = 1; v < V; ++v) {
    auto warped = homography_warp(features.select(1, v), proj.select(1, v), ref_proj, depth_values, config_.feature_warp);
    if (in_place) {
      volume_sum.add_(warped);
      volume_sq_sum.add_(warped.pow_(2));
    } else {
      volume_sum = volume_sum + warped;
      volume_sq_sum = volume_sq_sum + warped.pow(2);
    }
  }
  const double num_views = static_cast<double>(V);
  auto variance = in_place ? volume_sq_sum.div_(num_views).sub_(volume_sum.div_(num_views).pow_(2))
                           : volume_sq_sum / num_views - (volume_sum / num_views).pow(2);
  volume_sum = torch::Tensor();

  auto logits = cost_regularization(variance);
  auto prob = torch::softmax(logits, 1);
  MvsOutput out;
  out.depth_init = expected_depth(prob, depth_values);
  {
    torch::NoGradGuard no_grad;
    out.confidence = photometric_confidence(prob);
  }
  out.depth = refine_network ? refine_depth(images, out.depth_init, depth_values) : out.depth_init;
  if (keep_prob_volume) out.prob_volume = prob;
  return out;
}

}  // namespace umvs

namespace umvs {

double mvsnet_forward_flops(int H, int W, int D, int V, bool refine) {
  const double px = static_cast<double>(H) * W;
  // FeatureNet, per view: Cout*Cin*k*k*output pixels.
  const double feature = 8 * 3 * 9 * px + 8 * 8 * 9 * px + 16 * 8 * 25 * px / 4 + 2 * 16 * 16 * 9 * px / 4 +
                         32 * 16 * 25 * px / 16 + 2 * 32 * 32 * 9 * px / 16;
  // CostRegNet on N voxels at full volume resolution; each stride-2 level has N/8 of the previous.
  const double N = static_cast<double>(D) * (H / 4) * (W / 4);
  const double k = 27;
  const double costreg = k * (8 * 32 * N + (16 * 8 + 16 * 16) * N / 8 + (32 * 16 + 32 * 32) * N / 64 +
                              (64 * 32 + 64 * 64) * N / 512 +
                              64 * 32 * N / 512 + 32 * 16 * N / 64 + 16 * 8 * N / 8 +  // transposed: input voxels
                              1 * 8 * N);
  double refine_flops = 0;
  if (refine) refine_flops = 9 * (32 * 4 + 32 * 32 * 2 + 32) * px / 16;
  return 2.0 * (V * feature + costreg + refine_flops);
}

}  // namespace umvs
