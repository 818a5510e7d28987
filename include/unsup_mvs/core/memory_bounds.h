// Peak memory of one MVSNet depth map or training step on the CPU, estimated from the size of its
// cost volume, and the bounds that `umvs infer` and `umvs train` enforce with it, so that one call
// cannot drive a 24 GB machine out of memory (docs/reliability.md, "Resource bounds (command
// line)", has the measurements behind the coefficients).
#pragma once

#include <cstdint>

namespace umvs {

constexpr int kMaxDepthPlanes = 1024;
constexpr double kGiB = 1024.0 * 1024.0 * 1024.0;
constexpr double kMaxInferenceBytes = 12 * kGiB;
constexpr double kMaxTrainingBytes = 12 * kGiB;

// Network input width x height (the cost volume is at 1/4 of it), depth planes, views.
double estimated_inference_bytes(int width, int height, int num_depth, int views);
// The same for one training step of `batch` tuples (forward and backward pass, photometric loss
// over `views_loss` warped neighbours).
double estimated_training_bytes(int width, int height, int num_depth, int views_in, int views_loss, int batch);

// Throw std::invalid_argument naming the sizes, the estimate, the bound and what to reduce, when
// the estimate exceeds kMaxInferenceBytes / kMaxTrainingBytes or num_depth exceeds kMaxDepthPlanes.
void check_inference_memory(int width, int height, int num_depth, int views);
void check_training_memory(int width, int height, int num_depth, int views_in, int views_loss, int batch);

}  // namespace umvs
