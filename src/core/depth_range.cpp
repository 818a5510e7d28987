#include "unsup_mvs/core/depth_range.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/keyframes.h"

namespace umvs {

DepthRangeTracker::DepthRangeTracker(double depth_min, double depth_max) {
  if (!(std::isfinite(depth_min) && std::isfinite(depth_max) && depth_min > 0 && depth_max > depth_min)) {
    throw std::invalid_argument("depth range needs 0 < depth_min < depth_max, got " + std::to_string(depth_min) +
                                " - " + std::to_string(depth_max));
  }
  bounds_ = {depth_min, depth_max};
}

bool DepthRangeTracker::update(double near, double far) {
  if (!(std::isfinite(near) && std::isfinite(far))) {
    has_estimate_ = false;
    return false;
  }
  estimate_.near = std::max(bounds_.near, near);
  estimate_.far = std::min(bounds_.far, far);
  has_estimate_ = estimate_.far > estimate_.near * kMinFarOverNear;
  return has_estimate_;
}

bool DepthRangeTracker::update_from_samples(std::vector<float> depths) {
  double near = 0, far = 0;
  if (!depth_range_from_samples(std::move(depths), &near, &far)) return false;
  update(near, far);
  return true;
}

std::vector<float> confident_depths(const float* depth, const float* confidence, size_t n, float min_confidence) {
  std::vector<float> out;
  for (size_t i = 0; i < n; ++i) {
    if (confidence[i] > min_confidence) out.push_back(depth[i]);
  }
  return out;
}

}  // namespace umvs
