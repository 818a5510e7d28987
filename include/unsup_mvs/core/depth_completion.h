// Depth completion for the pixels the network is unsure about, label-free.
//
// Where no source view sees a point, or the surface has no texture (a plain wall), the cost
// volume holds no evidence and MVSNet's depth there is little more than a guess; its confidence
// says so (living room: abs rel 0.03-0.08 where confidence >= 0.5, 0.15-0.29 elsewhere,
// docs/results.md). Completion replaces those guesses by what the confident pixels around them
// imply: inverse depth is solved for as the smoothest field, by an edge-aware (image-guided)
// Laplacian, that keeps close to the estimates, each confident one weighing a thousand times
// an unsure one. A plane's inverse depth is an affine function of the pixel, which the Laplacian
// leaves unchanged, so a wall seen confidently around a hole is filled as the plane it is (at
// the image border, where no neighbour balances the pull of the inner ones, planes bend by about
// one pixel's change of depth). The guide image's edges stop the fill from bleeding across
// object boundaries. The depth of confident pixels moves a little too: the same smoothness
// evens out their noise.
#pragma once

#include <torch/types.h>

namespace umvs {

// The floor below which `umvs infer` and the inference nodelet complete by default: chosen on
// rendered scenes, then tested on others and on real images (docs/results.md). The core's own default (DepthCompletionConfig) stays off, so that training,
// the reload judge and the parity checks see the network's own depth.
inline constexpr double kRecommendedCompletionConfidence = 0.7;

struct DepthCompletionConfig {
  // Pixels below this confidence are completed from the others; 0 = off.
  double min_confidence = 0.0;
  // How strongly a grey-level step between neighbours (guide in [0,1]) cuts the smoothness
  // between them: weight exp(-step^2 / (2 sigma^2)).
  double edge_sigma = 0.025;

  bool enabled() const { return min_confidence > 0.0; }
  void validate() const;  // throws std::invalid_argument naming the field
};

struct DepthCompletionStats {
  double completed_share = 0.0;  // share of valid pixels below the confidence floor
  int iterations = 0;            // conjugate-gradient iterations
  bool converged = false;
};

// depth, confidence: float [h,w]; guide: the reference image's grey level at the depth pixels,
// float [h,w] in [0,1]. Returns the completed depth, float [h,w] on the CPU. Pixels whose depth is
// not a positive finite number stay as they are and hold nothing in place. When no pixel reaches
// the floor the depth is returned unchanged: there is nothing to complete from.
torch::Tensor complete_depth(const torch::Tensor& depth, const torch::Tensor& confidence, const torch::Tensor& guide,
                             const DepthCompletionConfig& config, DepthCompletionStats* stats = nullptr);

}  // namespace umvs
