// Weight-space interpolation between an adapted model and the model it was adapted from
// (WiSE-FT: Wortsman et al., "Robust fine-tuning of zero-shot models", CVPR 2022). A short
// label-free adaptation often moves the weights too far for the depth it improves, and its
// label-free judge cannot always tell (docs/results.md, the reload rule's audits). On rendered
// scenes the midpoint of the two models undid most of that damage, not all of it (same file).
#pragma once

#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

// model <- share * model + (1 - share) * start, for every parameter and every floating-point
// buffer (BatchNorm's running statistics); integer buffers (BatchNorm's step counter) keep the
// model's. share = 1 leaves the model as it is, 0 makes it `start`. `start` is read only; it may
// live on another device. Throws std::invalid_argument for a share outside [0, 1] or when the
// two models differ in a parameter's or buffer's name or shape (naming it): they must be one
// architecture.
void blend_weights(MvsNet& model, MvsNet& start, double share);

}  // namespace umvs
