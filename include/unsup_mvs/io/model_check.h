// A model checked before it serves: one small forward pass must give finite depth and confidence
// (a checkpoint can load and still hold weights that give NaN).
#pragma once

#include <torch/types.h>

#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

// A fronto-parallel camera pair of 64x64 random images with 8 planes. Throws std::runtime_error
// when the output is not finite.
void check_model_forward(const MvsNet& model, const torch::Device& device);

}  // namespace umvs
