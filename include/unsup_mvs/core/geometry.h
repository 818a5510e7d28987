// Tensor geometry shared by the cost-volume warp (no gradient needed) and the photometric loss's
// inverse warp (gradients flow into depth). Both start from `project_to_source`.
#pragma once

#include <torch/types.h>

#include <vector>

#include "unsup_mvs/core/camera.h"

namespace umvs {

enum class DepthSampling {
  kUniformDepth,         // MVSNet: planes evenly spaced in depth (good for object-scale ranges)
  kUniformInverseDepth,  // evenly spaced in 1/depth (robot scenes spanning 0.5 m to tens of m)
};
const char* to_string(DepthSampling s);
DepthSampling depth_sampling_from_string(const std::string& s);  // "depth" | "inverse_depth"

// Where the cost volume's homography warp samples a source feature map of width w.
enum class FeatureWarp {
  kExact,          // at the pixel the point projects to (grid_sample align_corners = true)
  kMvsNetPytorch,  // as MVSNet_pytorch runs on torch >= 1.3: its (w-1)/2 grid normalisation read
                   // with align_corners = false, i.e. at x*w/(w-1) - 0.5: half a feature pixel
                   // (two image pixels) off at the borders. Kept for its weights and parity.
};
const char* to_string(FeatureWarp w);
FeatureWarp feature_warp_from_string(const std::string& s);  // "exact" | "mvsnet_pytorch"

// D increasing depth hypotheses in [depth_min, depth_max], computed in float64 and rounded once
// to float32 (MVSNet's exact values for uniform sampling). Throws std::invalid_argument on
// non-positive, non-finite or empty ranges or D < 2.  -> [D] float32
torch::Tensor depth_hypotheses(double depth_min, double depth_max, int num_depth,
                               DepthSampling sampling);

// The continuous plane index of depths among hypotheses spanning depth_values' first to last
// entry with `sampling` (0 at the first plane, D-1 at the last; linear in depth or in 1/depth):
// errors in these units are errors in depth intervals, whatever the scene's scale.
//   depth [B,...] (> 0); depth_values [B,D]  -> [B,...]
torch::Tensor depth_to_plane_index(const torch::Tensor& depth, const torch::Tensor& depth_values,
                                   DepthSampling sampling);

// 4x4 [[K' R, K' t], [0 0 0 1]] with K' = K whose first two rows are multiplied by `scale`:
// MVSNet's naive feature-map scaling (feature pixel (i, j) sits on image pixel (i/scale, j/scale)),
// which the published weights were trained with.  -> [4,4] float32
torch::Tensor mvsnet_projection_matrix(const Camera& camera, double scale = 0.25);
// Stacked for several views.  -> [V,4,4] float32
torch::Tensor mvsnet_projection_matrices(const std::vector<Camera>& cameras, double scale = 0.25);

// Intrinsics and relative pose as tensors for the inverse warp.
torch::Tensor intrinsics_tensor(const Camera& camera);                         // [3,3] float32
torch::Tensor relative_pose_tensor(const Camera& ref, const Camera& src);      // [4,4] T_src_ref

// Pixel coordinates of every reference pixel with depth `depth` moved into the source camera.
//   K_ref, K_src: [B,3,3]; T_src_ref: [B,4,4]; depth: [B,H,W]
//   -> uv [B,H,W,2] (source pixel, column then row), z [B,H,W] (depth in the source camera)
struct SourceProjection {
  torch::Tensor uv;
  torch::Tensor z;
};
SourceProjection project_to_source(const torch::Tensor& K_ref, const torch::Tensor& K_src,
                                   const torch::Tensor& T_src_ref, const torch::Tensor& depth);

// Where a projection lands inside a width x height source image, in front of the camera: the
// pixels the photometric loss compares (inverse_warp's `valid`).  -> bool [B,H,W]
torch::Tensor inside_source(const SourceProjection& p, int64_t width, int64_t height);

// The part of MVSNet's homography that does not depend on depth: for every reference pixel
// (x, y) at feature resolution, rot_xyz = R (x, y, 1)^T and trans = t, where [R | t] are the top
// rows of src_proj * ref_proj^-1. The source point of depth d is rot_xyz * d + trans.
//   src_proj, ref_proj [B,4,4]  -> rot_xyz [B,3,H*W] (row-major pixels), trans [B,3,1]
struct HomographyRays {
  torch::Tensor rot_xyz;
  torch::Tensor trans;
};
HomographyRays homography_rays(const torch::Tensor& src_proj, const torch::Tensor& ref_proj, int64_t height,
                               int64_t width);

// MVSNet's differentiable homography warp of source features into the reference frustum.
//   src_features [B,C,H,W]; src_proj, ref_proj [B,4,4] (mvsnet_projection_matrix at feature
//   resolution); depth_values [B,D] (planes) or [B,D,H,W] (D hypotheses per pixel)  -> [B,C,D,H,W],
//   zero outside the source image.
// With FeatureWarp::kMvsNetPytorch it is bit-compatible with MVSNet_pytorch as run on torch >= 1.3.
torch::Tensor homography_warp(const torch::Tensor& src_features, const torch::Tensor& src_proj,
                              const torch::Tensor& ref_proj, const torch::Tensor& depth_values, FeatureWarp warp);

// Inverse warp for the photometric loss: sample `src_image` at the source pixel of every
// reference pixel with depth `depth` (bilinear, pixel-centre convention). Gradients flow into
// depth (and the image).
//   src_image [B,C,H,W]; K_ref, K_src [B,3,3]; T_src_ref [B,4,4]; depth [B,H,W] (> 0)
//   -> warped [B,C,H,W], valid [B,1,H,W] float (inside the source image and positive depth)
struct InverseWarp {
  torch::Tensor warped;
  torch::Tensor valid;
};
InverseWarp inverse_warp(const torch::Tensor& src_image, const torch::Tensor& K_ref,
                         const torch::Tensor& K_src, const torch::Tensor& T_src_ref,
                         const torch::Tensor& depth);

}  // namespace umvs
