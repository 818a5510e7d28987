// The depth network built for the CPU (MvsNetConfig::network == NetworkKind::kSweep2d): a
// plane-sweep cost volume regularised by a 2-D encoder-decoder, as DeepVideoMVS and SimpleRecon do,
// instead of MVSNet's 3-D U-Net.
//  - Features: a small 2-D net gives every view 16 matching and 32 context channels at 1/4 of the
//    input and the reference 16 channels at 1/2 (a skip for the last decoder stage).
//  - Cost: per plane and reference pixel, the cosine similarity of the reference's matching
//    features with each source's, sampled by the exact homography warp (geometry.h), averaged
//    over the sources: one number per plane, [B,D,h,w] (MVSNet's variance keeps 32 per plane).
//  - Regularisation: the D planes are channels of a 2-D encoder-decoder (four scales, 1/4 to
//    1/32, 32-128 channels), with the reference's context features concatenated in and its 1/2
//    features as a skip; the cost itself, scaled, is added to the logits (a matching prior);
//    it decodes to D logits per pixel at 1/2 of the input.
//  - Depth and confidence as MVSNet: softmax over the planes, soft-argmin, and the probability
//    mass of the 4 planes around the estimate.
// Normalisation is GroupNorm: the same numbers in training and at inference, whatever the batch
// (a robot fine-tunes on one or two tuples at a time).
// Upsampling is MVSNet's naive scaling (upsample2_naive): pixel (i, j) at 1/s sits on input pixel
// (s i, s j) at every scale, so the map's camera is depth_map_camera(network camera, 1/2).
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/modules/normalization.h>
#include <torch/nn/pimpl.h>

#include <vector>

#include "unsup_mvs/core/geometry.h"

namespace umvs {

// Conv2d (no bias) + GroupNorm (groups of 8 channels) + ReLU.
class ConvGnReLUImpl : public torch::nn::Module {
 public:
  ConvGnReLUImpl(int in, int out, int kernel = 3, int stride = 1);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
  torch::nn::GroupNorm norm{nullptr};
};
TORCH_MODULE(ConvGnReLU);

struct SweepFeatures {
  torch::Tensor matching;  // [N,16,H/4,W/4] compared across views by the cost volume
  torch::Tensor quarter;   // [N,32,H/4,W/4] the reference's skip at 1/4
  torch::Tensor half;      // [N,16,H/2,W/2] the reference's skip at 1/2
};

// [N,3,H,W] (normalised images) -> SweepFeatures.
class SweepFeatureNetImpl : public torch::nn::Module {
 public:
  SweepFeatureNetImpl();
  SweepFeatures forward(const torch::Tensor& image);
  static constexpr int kMatchingChannels = 16, kQuarterChannels = 32, kHalfChannels = 16;

 private:
  ConvGnReLU half0_{nullptr}, half1_{nullptr}, quarter0_{nullptr}, quarter1_{nullptr};
  torch::nn::Conv2d matching_{nullptr};
};
TORCH_MODULE(SweepFeatureNet);

// The 2-D encoder-decoder: cost [B,D,h,w] at 1/4, the reference's quarter [B,32,h,w] and half
// [B,16,2h,2w] features  -> logits [B,D,2h,2w]. h and w must be multiples of 8 (input multiples of 32).
class CostDecoder2DImpl : public torch::nn::Module {
 public:
  explicit CostDecoder2DImpl(int num_depth);
  torch::Tensor forward(const torch::Tensor& cost, const torch::Tensor& quarter, const torch::Tensor& half);
  int num_depth() const { return num_depth_; }

 private:
  int num_depth_;
  std::vector<ConvGnReLU> encoder_;  // one at 1/4, then pairs (stride 2, stride 1) at 1/8, 1/16, 1/32
  ConvGnReLU up16_{nullptr}, up8_{nullptr}, up4_{nullptr}, up2_{nullptr};
  torch::nn::Conv2d logits_{nullptr};
};
TORCH_MODULE(CostDecoder2D);

// The plane-sweep cost: per plane, the cosine similarity (over channels) of the reference's
// features with each source's features warped by homography_warp, averaged over the sources
// (0 where a source does not see the point). With autograd: torch ops, a slab of planes at a time;
// without it on the CPU: sampled straight from channels-last features, no warped volume built (the
// same numbers within float rounding).
//   features [B,V,C,h,w], view 0 the reference; proj [B,V,4,4] at that resolution;
//   depth_values [B,D]  -> [B,D,h,w] in [-1, 1]
torch::Tensor cosine_cost_volume(const torch::Tensor& features, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, FeatureWarp warp);

// Floating-point operations (2 x multiply-accumulates of the convolutions) of one forward pass of
// the 2-D network for V views of H x W with D planes.
double sweep_net_forward_flops(int height, int width, int num_depth, int num_views);

}  // namespace umvs
