// Inference-only forward pass of MVSNet for the CPU: the same network and the same numbers as
// MvsNetImpl::forward (within float rounding, tested against it), without its overheads:
//  - the variance cost volume is built in one pass (VarianceCostVolume): no warped source
//    volume is ever materialised, all cores work on it, and it is built a slab of planes at a
//    time, each slab going through the U-Net's first convolution at once (memory);
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
#include <vector>

#include "unsup_mvs/core/fine_pass.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

class FastMvsNet {
 public:
  // Floats of cost volume built at a time (32 MiB): large enough for oneDNN to run at full speed,
  // far below the whole volume (335 MiB at 640x512, D=128).
  static constexpr int64_t kDefaultSlabFloats = int64_t{8} << 20;

  // The model is put in eval() mode; its weights are folded now. slab_floats: see above (the
  // result does not depend on it).
  explicit FastMvsNet(MvsNet model, int64_t slab_floats = kDefaultSlabFloats);
  ~FastMvsNet();

  // Same arguments and result as MvsNetImpl::forward; runs without gradients. `times`
  // (optional) receives the stage times (only on the fast path, left untouched otherwise).
  MvsOutput forward(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values,
                    bool keep_prob_volume = false, MvsStageTimes* times = nullptr);

  // forward() with a fine pass after it (FinePassConfig, enabled): depth and confidence at
  // 1/fine.resolution_divisor of the input; `proj_fine` [B,V,4,4] are the projection matrices at that
  // scale. The confidence is the first pass's (photometric_confidence of its planes), interpolated
  // as the depth; depth_init is the first pass's depth at its own resolution. Any device.
  MvsOutput forward_coarse_to_fine(const torch::Tensor& images, const torch::Tensor& proj, const torch::Tensor& depth_values,
                                   const FinePassConfig& fine, const torch::Tensor& proj_fine,
                                   MvsStageTimes* times = nullptr);

  // Whether forward() takes the fast path for tensors on `device` (CPU with oneDNN).
  static bool accelerates(const torch::Device& device);

  MvsNet& model() { return model_; }
  const MvsNet& model() const { return model_; }

 private:
  struct FoldedUNet;
  // A pass's probability volume on the fast path: the cost volume built a slab at a time through
  // the folded U-Net, softmax over the planes; adds the seconds of each to t.cost_volume and
  // t.regularization.  features [B,V,C,h,w]; depth_values [B,D]  -> [B,D,h,w]
  torch::Tensor plane_probabilities(const torch::Tensor& features, const torch::Tensor& proj,
                                    const torch::Tensor& depth_values, MvsStageTimes& t);
  MvsNet model_;
  int64_t slab_floats_;
  std::unique_ptr<FoldedUNet> unet_;
};

// MVSNet's variance cost volume, built a range of planes at a time (so that the inference path
// never holds the whole 32-channel volume): for every plane and reference pixel, each source
// view is sampled at the coordinates homography_warp computes (bilinear, zero outside) and the
// mean and variance over all views, the reference included, are accumulated directly, in
// parallel over planes and rows. No warped source volume is materialised.
class VarianceCostVolume {
 public:
  // features [B,V,C,h,w] float32 CPU, view 0 the reference; proj [B,V,4,4]; depth_values [B,D]
  // (planes) or [B,D,h,w] (hypotheses per pixel)
  VarianceCostVolume(const torch::Tensor& features, const torch::Tensor& proj, const torch::Tensor& depth_values,
                     FeatureWarp warp);
  // Planes [begin, end) -> [B,C,end-begin,h,w]; planes outside [0, D) are zeros (convolution padding).
  torch::Tensor planes(int64_t begin, int64_t end) const;
  int64_t num_planes() const { return D_; }
  int64_t plane_elements() const { return B_ * C_ * H_ * W_; }  // floats per plane

 private:
  int64_t B_ = 0, V_ = 0, C_ = 0, H_ = 0, W_ = 0, D_ = 0;
  bool per_pixel_ = false;  // depth_ is [B,D,h,w]
  FeatureWarp warp_ = FeatureWarp::kExact;
  torch::Tensor features_;  // [B,V,h,w,C]
  torch::Tensor depth_;     // [B,D]
  std::vector<torch::Tensor> rot_xyz_, trans_;  // per source view: homography_rays [B,3,hw], [B,3]
};

// The whole volume at once (tests, small inputs): VarianceCostVolume(...).planes(0, D).
//   -> [B,C,D,h,w]
torch::Tensor variance_cost_volume(const torch::Tensor& features, const torch::Tensor& proj,
                                   const torch::Tensor& depth_values, FeatureWarp warp);

}  // namespace umvs
