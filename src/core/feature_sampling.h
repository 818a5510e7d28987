// Internal to core: the bilinear sample of a channels-last feature map at the point a homography
// maps a reference pixel to, with the arithmetic of homography_warp + ATen's CPU grid_sample (in
// the same order), for the cost volumes built without materialising warped features
// (VarianceCostVolume, the sweep2d network's cosine cost).
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "unsup_mvs/core/geometry.h"

namespace umvs::detail {

// The four taps of one sample: pointers to C contiguous floats (zeros outside the map) and weights.
struct FeatureTaps {
  const float *nw = nullptr, *ne = nullptr, *sw = nullptr, *se = nullptr;
  float w_nw = 0, w_ne = 0, w_sw = 0, w_se = 0;
};

class HomographySampler {
 public:
  // A feature map of h x w pixels and C channels, sampled as `warp` says.
  HomographySampler(int64_t height, int64_t width, int64_t channels, FeatureWarp warp)
      : H_(height), W_(width), C_(channels), zeros_(channels, 0.0f) {
    // A grid coordinate g maps to the pixel (g + 1) * (W - 1) / 2 with align_corners = true (exact)
    // and to (g + 1) * W / 2 - 0.5 with align_corners = false (MVSNet_pytorch).
    norm_x_ = static_cast<float>((W_ - 1) / 2.0);
    norm_y_ = static_cast<float>((H_ - 1) / 2.0);
    const bool exact = warp == FeatureWarp::kExact;
    scale_x_ = exact ? norm_x_ : static_cast<float>(W_) / 2;
    scale_y_ = exact ? norm_y_ : static_cast<float>(H_) / 2;
    shift_ = exact ? 0.0f : 0.5f;
  }

  // The taps into `src` ([h,w,C]) of the source point (px, py, pz) in homogeneous feature pixels;
  // false when every tap is outside (the sample is zero).
  bool taps(const float* src, float px, float py, float pz, FeatureTaps& t) const {
    float gx = px / pz / norm_x_ - 1.0f, gy = py / pz / norm_y_ - 1.0f;
    if (!std::isfinite(gx)) gx = -2.0f;  // a point on the source camera plane: outside
    if (!std::isfinite(gy)) gy = -2.0f;
    const float ix = (gx + 1.0f) * scale_x_ - shift_, iy = (gy + 1.0f) * scale_y_ - shift_;
    const float x_w = std::floor(ix), y_n = std::floor(iy);
    const bool west = x_w > -1 && x_w < W_, east = x_w > -2 && x_w < W_ - 1;
    const bool north = y_n > -1 && y_n < H_, south = y_n > -2 && y_n < H_ - 1;
    if (!((west || east) && (north || south))) return false;
    const float w = ix - x_w, e = 1.0f - w, n = iy - y_n, s = 1.0f - n;
    t.w_nw = s * e, t.w_ne = s * w, t.w_sw = n * e, t.w_se = n * w;
    const int64_t x0 = static_cast<int64_t>(x_w), y0 = static_cast<int64_t>(y_n);
    const auto tap = [&](bool in, int64_t yy, int64_t xx) { return in ? src + (yy * W_ + xx) * C_ : zeros_.data(); };
    t.nw = tap(north && west, y0, x0);
    t.ne = tap(north && east, y0, x0 + 1);
    t.sw = tap(south && west, y0 + 1, x0);
    t.se = tap(south && east, y0 + 1, x0 + 1);
    return true;
  }

 private:
  int64_t H_, W_, C_;
  float norm_x_, norm_y_, scale_x_, scale_y_, shift_;
  std::vector<float> zeros_;
};

}  // namespace umvs::detail
