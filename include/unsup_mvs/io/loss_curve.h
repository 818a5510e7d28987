// Loss-curve pictures for training logs (umvs train's loss_curve.png).
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <vector>

namespace umvs {

// Each series is drawn as a polyline over the step range on a log10 y axis, with a light grid at
// powers of ten and the y range written at the left edge.   -> uint8 [height,width,3]
struct CurveSeries {
  std::vector<double> x, y;
  uint8_t r = 0, g = 0, b = 0;
};
torch::Tensor render_curves(const std::vector<CurveSeries>& series, int width = 800, int height = 400);

}  // namespace umvs
