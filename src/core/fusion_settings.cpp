#include "unsup_mvs/core/fusion_settings.h"

namespace umvs {

const std::vector<Setting<FusionConfig>>& fusion_settings() {
  using C = FusionConfig;
  static const std::vector<Setting<C>> settings = {
      {"min_confidence", &C::min_confidence, 0.0, 1.0,
       "pixels with a lower network confidence are no estimate (0 = keep all)"},
      {"max_reprojection_px", &C::max_reprojection_px, 0.0, 100.0,
       "consistency: reprojection error after the round trip, in depth-map pixels (> 0)", true, {"max-reprojection"}},
      {"max_relative_depth", &C::max_relative_depth, 0.0, 1.0,
       "consistency: relative difference of the two depths after the round trip (> 0)"},
      {"min_agreeing_views", &C::min_agreeing_views, 0, 255,
       "other depth maps that must agree for a point to be kept", true, {"min-views"}},
      {"max_source_views", &C::max_source_views, 1, 255,
       "batch fusion: sources tested per reference, best first (pair.txt order)", false, {"max-sources"}},
      {"voxel_size", &C::voxel_size, 0.0, 10.0,
       "at most one point per voxel of this edge in scene units, the first fused wins (0 = off)", true, {"voxel"}},
      {"clear_after_views", &C::clear_after_views, 0, 255,
       "streaming fusion: a point leaves the cloud once this many estimates in a row see through it (0 = never)"},
      {"clear_margin", &C::clear_margin, 0.0, 1.0,
       "streaming fusion: seen through = farther than (1 + this) x the point's depth (> 0)"},
  };
  return settings;
}

}  // namespace umvs
