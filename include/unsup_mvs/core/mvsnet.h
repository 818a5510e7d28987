// MVSNet (Yao et al. 2018) in LibTorch. Module names follow MVSNet_pytorch (xy-guo), so its
// published weights import one-to-one (io/checkpoint.h).
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/batchnorm.h>
#include <torch/nn/modules/container/sequential.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/pimpl.h>

#include <string>
#include <vector>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/sweep_net.h"

namespace umvs {

// What the network does to its input images (colours in [0,1]) before the 2-D feature net.
enum class InputNormalization {
  kNone,              // as given (MVSNet_pytorch; its published weights expect this)
  kPerImageChannel,   // each view and colour channel to zero mean and unit variance: exposure,
                      // gain and white balance of the camera drop out (original MVSNet's
                      // center_image, per channel)
};
const char* to_string(InputNormalization n);
// "none" | "per_image_channel"; throws std::invalid_argument listing the accepted names.
InputNormalization input_normalization_from_string(const std::string& name);

// images [...,3,H,W] -> the same shape, normalised per image and channel over H x W.
torch::Tensor normalize_input_images(const torch::Tensor& images, InputNormalization normalization);

// Which network regularises the cost volume. Saved with checkpoints: a checkpoint selects its network.
enum class NetworkKind {
  kMvsNet,   // MVSNet: variance cost volume (32 channels per plane), 3-D U-Net, depth at 1/4
  kSweep2d,  // the CPU network (core/sweep_net.h): one cosine cost per plane, 2-D encoder-decoder,
             // depth at 1/2; its last layer has one output per plane, so num_depth is fixed by the weights
};
const char* to_string(NetworkKind n);
// "mvsnet" | "sweep2d"; throws std::invalid_argument listing the accepted names.
NetworkKind network_kind_from_string(const std::string& name);

// Planes of a new sweep2d network (DeepVideoMVS's 64, in inverse depth).
constexpr int kSweep2dDefaultPlanes = 64;

struct MvsNetConfig {
  NetworkKind network = NetworkKind::kMvsNet;
  // Depth hypotheses per reference view. The U-Net needs a multiple of 8. Not a property of the
  // weights: a model trained with 128 planes can run with 192 or 64.
  int num_depth = 128;
  DepthSampling depth_sampling = DepthSampling::kUniformDepth;
  // Refinement network (depth residual from the reference image and the initial depth).
  bool refine = false;
  // Views the network sees per depth map (reference + sources). Any V >= 2 works at inference.
  int num_views = 3;
  // Not a property of the weights' shapes but of what they were trained on: saved with checkpoints.
  InputNormalization input_normalization = InputNormalization::kNone;
  // Where the cost volume samples the source features (geometry.h). Saved with checkpoints too.
  FeatureWarp feature_warp = FeatureWarp::kExact;

  // Throws std::invalid_argument naming the bad field.
  void validate() const;
  // The depth map's grid: 1/4 of the input (MVSNet) or 1/2 (sweep2d).
  int map_divisor() const { return network == NetworkKind::kSweep2d ? 2 : 4; }
  // Whether the number of planes is fixed by the weights (sweep2d).
  bool planes_fixed_by_weights() const { return network == NetworkKind::kSweep2d; }
  // Fields that change the set of weights (network, `refine`, and num_depth for sweep2d); a checkpoint whose architecture
  // differs from the requested one cannot be loaded. Returns "" when compatible, else a message.
  std::string architecture_mismatch(const MvsNetConfig& other) const;
  std::string to_string() const;
};

// Conv + BatchNorm + ReLU (2-D or 3-D), as MVSNet_pytorch's ConvBnReLU / ConvBnReLU3D.
class ConvBnReLUImpl : public torch::nn::Module {
 public:
  ConvBnReLUImpl(int in, int out, int kernel = 3, int stride = 1, int pad = 1);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
  torch::nn::BatchNorm2d bn{nullptr};
};
TORCH_MODULE(ConvBnReLU);

class ConvBnReLU3DImpl : public torch::nn::Module {
 public:
  ConvBnReLU3DImpl(int in, int out, int kernel = 3, int stride = 1, int pad = 1);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv3d conv{nullptr};
  torch::nn::BatchNorm3d bn{nullptr};
};
TORCH_MODULE(ConvBnReLU3D);

// 2-D feature extractor: [B,3,H,W] in [0,1] -> [B,32,H/4,W/4].
class FeatureNetImpl : public torch::nn::Module {
 public:
  FeatureNetImpl();
  torch::Tensor forward(const torch::Tensor& image);
  static constexpr int kChannels = 32;

 private:
  std::vector<ConvBnReLU> layers_;  // conv0 .. conv6
  torch::nn::Conv2d feature_{nullptr};
};
TORCH_MODULE(FeatureNet);

// 3-D U-Net regularising the variance cost volume: [B,32,D,h,w] -> logits [B,D,h,w].
class CostRegNetImpl : public torch::nn::Module {
 public:
  CostRegNetImpl();
  torch::Tensor forward(const torch::Tensor& cost);

 private:
  ConvBnReLU3D conv0_{nullptr}, conv1_{nullptr}, conv2_{nullptr}, conv3_{nullptr},
      conv4_{nullptr}, conv5_{nullptr}, conv6_{nullptr};
  torch::nn::Sequential conv7_{nullptr}, conv9_{nullptr}, conv11_{nullptr};
  torch::nn::Conv3d prob_{nullptr};
};
TORCH_MODULE(CostRegNet);

// Depth residual from the reference image and the initial depth, both at 1/4 resolution.
// The depth is normalised by the depth range before and the residual scaled back after.
class RefineNetImpl : public torch::nn::Module {
 public:
  RefineNetImpl();
  // image [B,3,h,w]; depth [B,h,w]; depth_min/depth_max [B]  -> refined depth [B,h,w]
  torch::Tensor forward(const torch::Tensor& image, const torch::Tensor& depth,
                        const torch::Tensor& depth_min, const torch::Tensor& depth_max);

 private:
  ConvBnReLU conv1_{nullptr}, conv2_{nullptr}, conv3_{nullptr};
  torch::nn::Conv2d res_{nullptr};
};
TORCH_MODULE(RefineNet);

// Wall time of the stages of one forward pass, seconds (for `umvs bench`).
struct MvsStageTimes {
  double features = 0;        // 2-D feature net over all views
  double cost_volume = 0;     // warping + variance
  double regularization = 0;  // 3-D U-Net (MVSNet) or 2-D encoder-decoder (sweep2d) -> logits
  double regression = 0;      // softmax, soft-argmin depth, confidence
  double refinement = 0;      // refinement network (0 without)
  // Of the above, what the fine pass took (FastMvsNet::forward_coarse_to_fine; 0 without):
  double fine_cost_volume = 0, fine_regularization = 0;
};

// Maps at 1/s of the input, s = MvsNetConfig::map_divisor() (4 for MVSNet, 2 for sweep2d).
struct MvsOutput {
  torch::Tensor depth;        // [B,H/s,W/s] metres (refined when the network refines)
  torch::Tensor confidence;   // [B,H/s,W/s] probability mass of the 4 planes around the estimate
  torch::Tensor depth_init;   // [B,H/s,W/s] before refinement (== depth without refinement)
  torch::Tensor prob_volume;  // [B,D,H/s,W/s] (only when asked for)
};

class MvsNetImpl : public torch::nn::Module {
 public:
  explicit MvsNetImpl(const MvsNetConfig& config = {});

  // images [B,V,3,H,W] in [0,1], view 0 the reference, H and W multiples of 32;
  // proj [B,V,4,4] mvsnet_projection_matrices (feature scale 0.25); depth_values [B,D] increasing.
  MvsOutput forward(const torch::Tensor& images, const torch::Tensor& proj,
                    const torch::Tensor& depth_values, bool keep_prob_volume = false);

  // The pieces of forward() that the inference path (core/fast_mvsnet.h) shares with it:
  // throws c10::Error naming the bad argument of forward();
  static void check_inputs(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values);
  // the 2-D features of every view: images as forward()  -> [B,V,32,H/4,W/4];
  torch::Tensor view_features(const torch::Tensor& images);
  // the refinement network's depth (config.refine only): images as forward(), depth_init
  // [B,H/4,W/4], depth_values [B,D]  -> [B,H/4,W/4].
  torch::Tensor refine_depth(const torch::Tensor& images, const torch::Tensor& depth_init,
                             const torch::Tensor& depth_values);

  const MvsNetConfig& config() const { return config_; }
  // The hypotheses count used by forward() is taken from depth_values; this only updates the
  // config that is saved with checkpoints and used by callers to build depth_values. A sweep2d
  // network's planes are fixed by its weights: another count throws std::invalid_argument.
  void set_num_depth(int d);
  void set_depth_sampling(DepthSampling s) { config_.depth_sampling = s; }
  void set_feature_warp(FeatureWarp w) { config_.feature_warp = w; }

  FeatureNet feature{nullptr};                // MVSNet only
  CostRegNet cost_regularization{nullptr};    // MVSNet only
  RefineNet refine_network{nullptr};          // null unless config.refine
  SweepFeatureNet sweep_features{nullptr};    // sweep2d only
  CostDecoder2D cost_decoder{nullptr};        // sweep2d only

  // forward() of a sweep2d network; `times` (optional) receives its stages' wall time.
  MvsOutput forward_sweep2d(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values,
                            bool keep_prob_volume, MvsStageTimes* times = nullptr);

 private:
  MvsNetConfig config_;
};
TORCH_MODULE(MvsNet);

// Soft-argmin and the photometric confidence of a probability volume.
//   prob [B,D,h,w] (softmax over D); depth_values [B,D]  -> depth [B,h,w], confidence [B,h,w]
// confidence = prob[i-1] + prob[i] + prob[i+1] + prob[i+2] at i = floor(sum_d prob[d] * d),
// planes outside [0, D-1] counting as 0 (MVSNet_pytorch's photometric_confidence).
torch::Tensor expected_depth(const torch::Tensor& prob, const torch::Tensor& depth_values);
torch::Tensor photometric_confidence(const torch::Tensor& prob);

}  // namespace umvs

namespace umvs {
// Floating-point operations (2 x multiply-accumulates of the convolutions; warping and softmax
// are small in comparison and not counted) of one forward pass for V views of H x W with D planes.
double mvsnet_forward_flops(int height, int width, int num_depth, int num_views, bool refine = false);
}  // namespace umvs
