// The depth range that the keyframe selector sends with each keyframe set: the configured bounds
// [depth_min, depth_max] until a depth estimate gives a usable range, then that range clamped to
// the bounds. ROS-free; the keyframe_selector nodelet holds one (under its own mutex).
#pragma once

#include <cstddef>
#include <vector>

namespace umvs {

struct DepthRange {
  double near = 0;
  double far = 0;
};

// Not thread-safe: the caller serialises update() and range().
class DepthRangeTracker {
 public:
  // A clamped estimate narrower than this ratio (far <= near * kMinFarOverNear) is no range:
  // the configured bounds are used again.
  static constexpr double kMinFarOverNear = 1.05;
  // Pixels whose confidence is above this take part in the estimate (DepthEstimate.confidence).
  static constexpr float kMinConfidence = 0.5f;

  // Throws std::invalid_argument unless 0 < depth_min < depth_max (both finite).
  DepthRangeTracker(double depth_min, double depth_max);

  // The range for the next keyframe set: the last estimate when there is one, else the bounds.
  DepthRange range() const { return has_estimate_ ? estimate_ : bounds_; }
  const DepthRange& bounds() const { return bounds_; }
  bool has_estimate() const { return has_estimate_; }

  // A new estimate [near, far] (e.g. from depth_range_from_samples): clamped to the bounds (a
  // bad estimate must not shrink the search for good); when the clamped range is narrower than
  // kMinFarOverNear, or either end is not finite, the tracker falls back to the bounds. Returns
  // has_estimate().
  bool update(double near, double far);

  // The estimate from a depth map's samples: depth_range_from_samples (2nd/98th percentiles of
  // the finite positive depths, 20 % margin, at least 100 of them) then update(). With too few
  // usable depths the previous range (estimate or bounds) is kept and false is returned; else
  // the estimate is taken and true is returned (has_estimate() says whether it is in use).
  bool update_from_samples(std::vector<float> depths);

 private:
  DepthRange bounds_;
  DepthRange estimate_;
  bool has_estimate_ = false;
};

// The depths of the pixels whose confidence is above `min_confidence`, in pixel order.
// `depth` and `confidence` hold `n` values each.
std::vector<float> confident_depths(const float* depth, const float* confidence, size_t n,
                                    float min_confidence = DepthRangeTracker::kMinConfidence);

}  // namespace umvs
