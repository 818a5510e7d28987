// The fine pass of a coarse-to-fine depth estimate (FastMvsNet::forward_coarse_to_fine): its
// settings, its per-pixel hypotheses, and the cost volume over them.
#pragma once

#include <torch/types.h>

#include <utility>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

// A second pass of the same network around the first pass's depth: coarse to fine, as CasMVSNet,
// with the one set of weights. Per pixel, `planes` hypotheses evenly spread over `span` of the
// first pass's plane intervals (in its sampling: depth or inverse depth), centred on its depth
// and moved inside the depth range at its ends; the cost volume is built on the features at
// 1/`resolution_divisor` of the input (at 1/2 the 1/4-resolution features, interpolated, sampled
// at twice the positions). What it buys is a cheap first pass: at half the input's size it is a
// quarter of the work, and the map keeps the full input's resolution (docs/results.md measures
// what that costs in depth). The refinement network (MvsNetConfig::refine) does not run after a
// fine pass.
struct FinePassConfig {
  int planes = 0;              // multiple of 8; 0 = no fine pass
  double span = 4.0;           // first-pass plane intervals covered, > 0
  int resolution_divisor = 4;  // 4 (the first pass's resolution) or 2 (half the input's)
  // 1: the first pass sees the input as given; 2: the input scaled to half its width and height
  // (a quarter of the work; depth at 1/8, interpolated for the fine pass).
  int first_pass_downscale = 1;

  bool enabled() const { return planes > 0; }
  void validate() const;  // throws std::invalid_argument naming the field
};

// Per pixel hypotheses of a fine pass (FinePassConfig) around `depth` [B,h,w], the first pass's
// estimate, whose planes were depth_values [B,D] with `sampling`.  -> [B,planes,h,w] increasing
torch::Tensor fine_pass_hypotheses(const torch::Tensor& depth, const torch::Tensor& depth_values, DepthSampling sampling,
                                   const FinePassConfig& fine);

// [B,C,h,w] -> [B,C,2h,2w] under MVSNet's naive scaling: output pixel 2i is input pixel i, output
// 2i+1 the mean of inputs i and i+1 (the last row and column repeat).
torch::Tensor upsample2_naive(const torch::Tensor& x);

// MVSNet's variance cost volume over per-view features warped with torch ops (any device; the
// fast CPU path of the first pass is VarianceCostVolume).
//   features [B,V,C,h,w], view 0 the reference; proj [B,V,4,4] at that resolution;
//   hypotheses [B,D] or [B,D,h,w]  -> [B,C,D,h,w]
torch::Tensor variance_volume_by_warps(const torch::Tensor& features, const torch::Tensor& proj,
                                       const torch::Tensor& hypotheses, FeatureWarp warp);

// Throws c10::Error naming the bad argument of a coarse-to-fine forward pass: images, proj and
// depth_values as MvsNetImpl::forward; proj_fine [B,V,4,4] at 1/fine.resolution_divisor; with a
// half-size first pass the input's width and height must be multiples of 64.
void check_coarse_to_fine_inputs(const torch::Tensor& images, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, const FinePassConfig& fine,
                                 const torch::Tensor& proj_fine);

// The first pass's views at half the input's size: images [B,V,3,H,W] box-filtered 2x2, and proj
// [B,V,4,4] with its first two rows halved (they scale with the features).
std::pair<torch::Tensor, torch::Tensor> half_size_views(const torch::Tensor& images, const torch::Tensor& proj);

// The first pass's depth and confidence [B,h,w], and the views' features [B,V,C,h',w'] at 1/4 of
// the input, brought to the fine pass's grid (naive 2x steps, upsample2_naive).
struct FineGrid {
  torch::Tensor depth, confidence, features;
};
FineGrid to_fine_grid(const torch::Tensor& depth, const torch::Tensor& confidence, const torch::Tensor& features,
                      const FinePassConfig& fine);

// Both passes with the model's own modules and torch ops, differentiable for training (the fine
// pass's hypotheses are detached from the first pass, as in CasMVSNet): the reference of the fast
// inference path (FastMvsNet::forward_coarse_to_fine), which it runs off the fast CPU route.
//   -> depth [B,H/d,W/d] (d = resolution_divisor); depth_init: the first pass's depth at its own
//   1/4 (or 1/8) grid; confidence: the first pass's, on the map's grid. No refinement network.
MvsOutput coarse_to_fine_forward(MvsNetImpl& model, const torch::Tensor& images, const torch::Tensor& proj,
                                 const torch::Tensor& depth_values, const FinePassConfig& fine,
                                 const torch::Tensor& proj_fine);

}  // namespace umvs
