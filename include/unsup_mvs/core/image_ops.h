// Image tensors: conversion, resizing for the network, false-colour previews.
#pragma once

#include <torch/types.h>

#include "unsup_mvs/core/camera.h"

namespace umvs {

// uint8 [H,W,3] -> float32 [3,H,W] in [0,1] (value / 255 with IEEE division, as MVSNet reads images).
torch::Tensor rgb8_to_float(const torch::Tensor& rgb8);
// float [3,H,W] in [0,1] -> uint8 [H,W,3] (rounded, clamped).
torch::Tensor float_to_rgb8(const torch::Tensor& image);

// Resize float [C,H,W] (or [B,C,H,W]) to width x height: area averaging when shrinking (no
// aliasing), bilinear when enlarging.
torch::Tensor resize_image(const torch::Tensor& image, int width, int height);
// Resize then crop as planned by plan_network_resize (camera.h): float [C,H,W] -> [C,h,w].
torch::Tensor apply_network_resize(const torch::Tensor& image, const NetworkResize& plan);

// Values [H,W] mapped from [lo, hi] onto a blue-to-red colour ramp (jet); pixels where `valid` is
// false (or the value is not finite) are black.  -> uint8 [H,W,3]
torch::Tensor colorize(const torch::Tensor& values, double lo, double hi,
                       const torch::Tensor& valid = torch::Tensor());

}  // namespace umvs
