// Inference-only forward pass of MVSNet for the CPU: the same network and the same numbers as
// MvsNetImpl::forward (within float rounding, tested against it), without its overheads:
//  - the variance cost volume is built in one pass (variance_cost_volume): no warped source
//    volume is ever materialised, and all cores work on it;
//  - BatchNorm is folded into the 3-D convolutions once, at construction; ReLU works in place;
//  - every 3-D convolution runs on oneDNN, and each stride-2 transposed convolution as 8
//    sub-pixel convolutions (LibTorch 1.13 sends small conv3d and every conv_transpose3d to a
//    slow im2col path).
// The 2-D features and the refinement come from the model itself (MvsNetImpl::view_features,
// MvsNetImpl::refine_depth), so what forward() does to the images applies here too.
// On other devices (CUDA) and without oneDNN, forward() is MvsNetImpl::forward (torch ops).
//
// The folded weights are a snapshot: build a new FastMvsNet after changing the model's weights.
// Training keeps MvsNetImpl::forward (autograd).
#pragma once

#include <torch/types.h>

#include <memory>

#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

// Wall time of the stages of one forward pass, seconds (for `umvs bench`).
struct MvsStageTimes {
  double features = 0;        // 2-D feature net over all views
  double cost_volume = 0;     // warping + variance
  double regularization = 0;  // 3-D U-Net -> logits
  double regression = 0;      // softmax, soft-argmin depth, confidence
  double refinement = 0;      // refinement network (0 without)
};

class FastMvsNet {
 public:
  // The model is put in eval() mode; its weights are folded now.
  explicit FastMvsNet(MvsNet model);
  ~FastMvsNet();

  // Same arguments and result as MvsNetImpl::forward; runs without gradients. `times`
  // (optional) receives the stage times (only on the fast path, left untouched otherwise).
  MvsOutput forward(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values,
                    bool keep_prob_volume = false, MvsStageTimes* times = nullptr);

  // Whether forward() takes the fast path for tensors on `device` (CPU with oneDNN).
  static bool accelerates(const torch::Device& device);

  MvsNet& model() { return model_; }
  const MvsNet& model() const { return model_; }

 private:
  struct FoldedUNet;
  MvsNet model_;
  std::unique_ptr<FoldedUNet> unet_;
};

// MVSNet's variance cost volume in one pass: for every plane and reference pixel, each source
// view is sampled at the coordinates homography_warp computes (bilinear, zero outside) and the
// mean and variance over all views, the reference included, are accumulated directly.
//   features [B,V,C,h,w] float32 CPU, view 0 the reference; proj [B,V,4,4]; depth_values [B,D]
//   -> [B,C,D,h,w]
torch::Tensor variance_cost_volume(const torch::Tensor& features, const torch::Tensor& proj,
                                   const torch::Tensor& depth_values);

}  // namespace umvs
