#include "unsup_mvs/core/memory_bounds.h"

#include <cstdio>
#include <stdexcept>
#include <string>

namespace umvs {

namespace {

// Peak resident sets (VmHWM) measured on the development machine (CPU LibTorch 1.13, 2 threads;
// docs/reliability.md lists the runs), fitted as base + bytes per input pixel + bytes per
// cost-volume cell ((W/4) x (H/4) x D).
// Inference: 320x256 and 640x512 with 64 and 128 planes, 3 and 5 views (the views hardly matter:
// the variance volume is accumulated view by view).
constexpr double kInferenceBaseBytes = 180.0 * 1024 * 1024;
constexpr double kInferenceBytesPerPixel = 116.0;
constexpr double kInferenceBytesPerCell = 468.0;
// Training (forward + backward, Adam): 160x128 and 320x256, 32 and 64 planes, 3 and 5 network
// views, 4 loss views. Larger sizes are extrapolated, so the fitted terms get a margin of 1.5.
constexpr double kTrainingBaseBytes = 225.0 * 1024 * 1024;
constexpr double kTrainingBytesPerPixelPerLossView = 830.0;
constexpr double kTrainingBytesPerPixelPerView = 1131.0;
constexpr double kTrainingBytesPerCellPerView = 109.0;
constexpr double kTrainingMargin = 1.5;

double cells(int width, int height, int num_depth) {
  return static_cast<double>(width / 4) * static_cast<double>(height / 4) * num_depth;
}

std::string gib(double bytes) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f GiB", bytes / kGiB);
  return buf;
}

void check(double estimate, double bound, int width, int height, int num_depth, const std::string& what,
           const std::string& reduce) {
  if (num_depth > kMaxDepthPlanes) {
    throw std::invalid_argument(what + ": " + std::to_string(num_depth) + " depth planes, more than the " +
                                std::to_string(kMaxDepthPlanes) + " accepted");
  }
  if (estimate > bound) {
    throw std::invalid_argument(what + " at " + std::to_string(width) + "x" + std::to_string(height) + " with " +
                                std::to_string(num_depth) + " depth planes needs about " + gib(estimate) +
                                " of memory, more than the " + gib(bound) + " accepted (docs/reliability.md): " + reduce);
  }
}

}  // namespace

double estimated_inference_bytes(int width, int height, int num_depth, int views) {
  (void)views;
  return kInferenceBaseBytes + kInferenceBytesPerPixel * width * static_cast<double>(height) +
         kInferenceBytesPerCell * cells(width, height, num_depth);
}

double estimated_training_bytes(int width, int height, int num_depth, int views_in, int views_loss, int batch) {
  const double pixels = static_cast<double>(width) * height;
  const double per_tuple = pixels * (kTrainingBytesPerPixelPerLossView * views_loss + kTrainingBytesPerPixelPerView * views_in) +
                           kTrainingBytesPerCellPerView * views_in * cells(width, height, num_depth);
  return kTrainingBaseBytes + kTrainingMargin * per_tuple * batch;
}

void check_inference_memory(int width, int height, int num_depth, int views) {
  check(estimated_inference_bytes(width, height, num_depth, views), kMaxInferenceBytes, width, height, num_depth,
        "a depth map", "scale the images down (--max-width/--max-height) or use fewer planes (--num-depth)");
}

void check_training_memory(int width, int height, int num_depth, int views_in, int views_loss, int batch) {
  check(estimated_training_bytes(width, height, num_depth, views_in, views_loss, batch), kMaxTrainingBytes, width,
        height, num_depth, "a training step of " + std::to_string(batch) + " x " + std::to_string(views_in) + " views",
        "use a smaller --width/--height, fewer --num-depth planes, --views-in or --batch");
}

}  // namespace umvs
