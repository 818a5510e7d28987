// The depth estimator settings the product starts from: the inference nodelet's defaults, `umvs
// infer`'s, and what `umvs bench --case pipeline` times.
#pragma once

#include "unsup_mvs/core/depth_estimator.h"

namespace umvs {

// At most 640x512 (the default model's training size), planes following the input, one pass per
// source where the one pass is unsure, the unsure pixels completed from the confident ones.
inline DepthEstimatorConfig recommended_estimator_config() {
  DepthEstimatorConfig c;
  c.max_width = 640;
  c.max_height = 512;
  c.completion.min_confidence = kRecommendedCompletionConfidence;
  c.source_combination = kRecommendedSourceCombination;
  return c;
}

}  // namespace umvs
