// The unsupervised multi-view loss of Khot et al. 2019 ("Learning Unsupervised Multi-View
// Stereopsis via Robust Photometric Consistency"): source views are inverse-warped into the
// reference with the predicted depth (geometry.h: inverse_warp, gradients flow into depth) and
// compared with the reference per pixel and view.
//
//   naive photometric (eq. 3):  mean_c |I - I'|
//   first-order (eq. 4):        mean_c huber(I - I') + mean_c (|dx I - dx I'| + |dy I - dy I'|)
//   robust aggregation (eq. 5): per pixel keep the K smallest of the M view losses (invalid
//                               entries count as a large value), average over the valid kept ones
//   SSIM:                       (1 - SSIM)/2 clipped to [0,1] on the 2 best-ranked loss views
//                               (the first two, in view-selection order), 3x3 average pooling
//   smoothness:                 |dx D| exp(-mean_c |dx I|) + |dy D| exp(-mean_c |dy I|)
//   total = alpha * photometric + beta * SSIM + gamma * smoothness
//
// All maps live on one pixel grid (the caller decides which: `umvs train` uses the network's
// 1/4-resolution depth grid, see docs/training.md). Masks are float {0,1}.
#pragma once

#include <torch/types.h>

#include <string>

#include "unsup_mvs/core/geometry.h"

namespace umvs {

enum class PhotometricTerm {
  kNaive,       // L1 on colour (eq. 3)
  kFirstOrder,  // Huber on colour + L1 (or Huber) on image gradients (eq. 4)
};
const char* to_string(PhotometricTerm t);

struct LossConfig {
  PhotometricTerm term = PhotometricTerm::kFirstOrder;
  // Views kept per pixel by the robust aggregation; 0 (or >= M) keeps all views.
  int top_k = 3;
  // Huber threshold on the colour difference (colours in [0,1]); the gradient term is L1 when
  // huber_delta_gradient is 0. The paper does not state its threshold; 0.1 keeps the quadratic
  // zone below ~25 grey levels.
  double huber_delta_intensity = 0.1;
  double huber_delta_gradient = 0.0;
  // Entries of invalid (out-of-image) pixels before the top-K selection.
  double invalid_value = 1e4;
  // Loss views used by the SSIM term (the first ones in view-selection order).
  int ssim_views = 2;
  // Normalise every image (each view separately) to zero mean, unit std before comparing (the
  // authors' released code); the smoothness edge weights then see normalised gradients too.
  bool normalize_images = false;
  double alpha = 0.8;      // photometric
  double beta = 0.2;       // SSIM
  double gamma = 0.0067;   // smoothness (on depth divided by its mean: scale-free)

  // The paper's weights (the defaults above).
  static LossConfig paper();
  // The authors' released code: 12 / 6 / 0.18, Huber 0.6 on colour and 0.2 on gradients,
  // per-image normalised inputs.
  static LossConfig authors_code();
  // Throws std::invalid_argument naming the field.
  void validate() const;
  std::string to_string() const;
};

// Per-pixel, per-view photometric loss of one warped view.
//   ref, warped [B,C,H,W]; valid [B,1,H,W]  -> loss [B,H,W], valid [B,H,W] (pixels where every
//   value the loss reads is valid: the gradient term also needs the right and lower neighbour)
struct LossMap {
  torch::Tensor loss;
  torch::Tensor valid;
};
LossMap photometric_loss_map(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid,
                             const LossConfig& config);

// Robust aggregation (eq. 5): losses, valid [B,M,H,W]; top_k in 1..M (0 = M).
// Returns sum of the kept valid entries / their number (0 when none is valid).  -> scalar
torch::Tensor top_k_aggregate(const torch::Tensor& losses, const torch::Tensor& valid, int top_k,
                              double invalid_value = 1e4);

// Per-pixel (1 - SSIM)/2 of 3x3 windows, averaged over channels, and the windows whose nine pixels
// are all valid.  ref, warped [B,C,H,W]; valid [B,1,H,W]  -> both [B,1,H,W]
struct SsimLossMap {
  torch::Tensor loss;
  torch::Tensor window_valid;  // float 0/1
};
SsimLossMap ssim_loss_map(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid);

// Mean of ssim_loss_map over its valid windows.  -> scalar
torch::Tensor ssim_loss(const torch::Tensor& ref, const torch::Tensor& warped, const torch::Tensor& valid);

// Standard deviation of each 3x3 window, averaged over channels.  image [B,C,H,W] -> [B,1,H,W]
torch::Tensor local_std(const torch::Tensor& image);

// Edge-aware smoothness of depth [B,H,W] given the reference image [B,C,H,W]  -> scalar.
// Depth is divided by its per-image mean first, so the weight does not depend on scene units.
torch::Tensor smoothness_loss(const torch::Tensor& depth, const torch::Tensor& image);

// Supervised depth loss (MVSNet's smooth L1) on the pixels with ground truth (gt > 0): the
// estimate and the truth are compared in plane indices (geometry.h: depth_to_plane_index), so
// one unit is one depth interval and scenes of any scale weigh alike; smooth L1 is quadratic
// below one interval. Mean over the pixels with ground truth, 0 when there is none.
//   depth, gt [B,H,W]; depth_values [B,D] the network's hypotheses  -> scalar
torch::Tensor supervised_depth_loss(const torch::Tensor& depth, const torch::Tensor& gt,
                                    const torch::Tensor& depth_values, DepthSampling sampling);

// Entropy of each pixel's distribution over the depth planes, divided by log(D): 0 when all the
// probability is on one plane, 1 when it is spread evenly. The robust loss sees only the expected
// depth, so nothing in it keeps the volume peaked; a small weight on this mean does (a label-free
// regulariser for fine-tuning: docs/training.md).  prob [B,D,H,W] (softmax over D)  -> [B,H,W]
torch::Tensor normalized_plane_entropy(const torch::Tensor& prob);

// The robust photometric loss of every reference pixel as if its depth were each plane's: per
// plane d, the first-order term of each loss view warped at depth_values[:, d], and per pixel the
// mean of its top-K valid views (config.top_k; 0 = all). No gradients: the planes are fixed.
//   ref_image [B,3,H,W]; src_images [B,M,3,H,W]; cameras as unsupervised_loss; depth_values [B,D]
//   -> loss [B,D,H,W], valid [B,D,H,W] (float 0/1: at least one valid view kept)
struct PlaneLosses {
  torch::Tensor loss;
  torch::Tensor valid;
};
PlaneLosses plane_photometric_losses(const torch::Tensor& ref_image, const torch::Tensor& src_images,
                                     const torch::Tensor& K_ref, const torch::Tensor& K_src,
                                     const torch::Tensor& T_src_ref, const torch::Tensor& depth_values,
                                     const LossConfig& config);

// The photometric loss the network's distribution expects: sum_d prob[d] * loss[d], averaged over
// the pixels that are valid on every plane (0 when there is none). Lower when the probability sits
// on the planes where the views agree; where every plane looks alike it does not care how the
// probability is spread (unlike normalized_plane_entropy).  prob [B,D,H,W]  -> scalar
torch::Tensor expected_plane_loss(const torch::Tensor& prob, const PlaneLosses& planes);

struct LossTerms {
  torch::Tensor total;        // scalar, differentiable
  torch::Tensor photometric;  // scalar (after top-K)
  torch::Tensor ssim;         // scalar
  torch::Tensor smoothness;   // scalar
  torch::Tensor valid_fraction;  // scalar: fraction of (pixel, kept view) entries that were valid
};

// The full loss.
//   ref_image [B,3,H,W]; src_images [B,M,3,H,W] (colours in [0,1])
//   K_ref [B,3,3]; K_src [B,M,3,3]; T_src_ref [B,M,4,4] (source-from-reference)
//   depth [B,H,W] (> 0, same grid as the images)
LossTerms unsupervised_loss(const torch::Tensor& ref_image, const torch::Tensor& src_images,
                            const torch::Tensor& K_ref, const torch::Tensor& K_src,
                            const torch::Tensor& T_src_ref, const torch::Tensor& depth,
                            const LossConfig& config);

}  // namespace umvs
