// What batch fusion (fusion.cpp) and streaming fusion (streaming_fusion.cpp) share: a view as
// fusion holds it, and the steps both run on it. Internal to core; see unsup_mvs/core/fusion.h.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <unordered_set>
#include <vector>

#include "unsup_mvs/core/fusion.h"

namespace umvs {
namespace fusion_detail {

// A view's tensors on the fusion device, cleaned: depth is 0 where it is no estimate.
struct Prepared {
  int64_t id = 0;
  Camera camera;
  torch::Tensor depth;         // [H,W] float32
  torch::Tensor valid;         // [H,W] bool
  torch::Tensor confidence;    // [H,W] float32
  torch::Tensor color;         // [H,W,3] uint8
  torch::Tensor source_depth;  // [H,W] float32: what the view offers as a source (== depth, or
                               // with kMvsnetEval every finite positive depth, confident or not)
  torch::Tensor quad_valid;    // CPU, default rule: quad_validity(valid), for its use as a source
};

// Per source pixel: whether it and its right, lower and lower-right neighbours are all estimates
// (0 on the last row and column). [H,W] uint8 on the CPU.
torch::Tensor quad_validity(const torch::Tensor& valid);
// Checks shapes and the camera; throws std::invalid_argument naming the view.
void validate_view(const FusionView& v);
Prepared prepare(const FusionView& v, const FusionConfig& config, const torch::Device& device);
// The points of the pixels `keep` of a view, at `depth`, with `count` agreeing views.
PointCloud make_points(const Prepared& p, const torch::Tensor& keep, const torch::Tensor& depth, const torch::Tensor& count);
int64_t voxel_key(const Eigen::Vector3f& p, double voxel);
// The points whose voxel is not in `voxels` yet (the first of a voxel wins); adds their voxels.
PointCloud voxel_filter(const PointCloud& in, double voxel, std::unordered_set<int64_t>& voxels);
// Accumulates the agreement of `sources` into `count` and `depth_sum` of reference `ref`.
void accumulate(const Prepared& ref, const std::vector<const Prepared*>& sources, const FusionConfig& config,
                torch::Tensor& count, torch::Tensor& depth_sum);

}  // namespace fusion_detail
}  // namespace umvs
