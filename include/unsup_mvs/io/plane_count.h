// How many depth planes inference sweeps: the user's count, or a default that follows the size
// of the network input, never the count a checkpoint happened to be trained or fine-tuned with;
// except for a network whose weights fix the count (sweep2d), which always sweeps its own.
#pragma once

#include <algorithm>
#include <string>

#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

struct PlaneCount {
  int planes = 0;
  std::string why;  // for the log: "128 planes (default for a 640x512 network input)"
};

// MVSNet's settings: 128 planes at 640x512 (training) and 192 at 1600x1200 (DTU evaluation). The
// default scales 128 with the input width, rounded to a multiple of 8, within 16..192.
inline int default_plane_count(int width) {
  const int scaled = static_cast<int>(128.0 * width / 640.0 / 8.0 + 0.5) * 8;
  return std::clamp(scaled, 16, 192);
}

// The default for `model`: its own count when its weights fix it, else default_plane_count(width).
inline int default_plane_count(const MvsNetConfig& model, int width) {
  return model.planes_fixed_by_weights() ? model.num_depth : default_plane_count(width);
}

// `requested` != 0 wins (DepthEstimator refuses what is not a positive multiple of 8); `option`
// names where it comes from ("--num-depth", "~num_depth"); `checkpoint_planes` is only reported.
inline PlaneCount choose_plane_count(int requested, const std::string& option, int width, int height,
                                     int checkpoint_planes, bool planes_fixed = false) {
  const std::string trained = "; the checkpoint was trained with " + std::to_string(checkpoint_planes);
  if (planes_fixed && requested == 0) {
    return {checkpoint_planes, std::to_string(checkpoint_planes) + " planes (fixed by the network's weights)"};
  }
  if (requested != 0) return {requested, std::to_string(requested) + " planes (" + option + trained + ")"};
  const int planes = default_plane_count(width);
  return {planes, std::to_string(planes) + " planes (default for a " + std::to_string(width) + "x" +
                      std::to_string(height) + " network input: 128 at 640 wide, scaled with the width, 16..192" +
                      trained + "; " + option + " to change)"};
}

}  // namespace umvs
