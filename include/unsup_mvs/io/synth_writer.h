// Writes a synthetic scene (core/synth.h) as an MVSNet-format folder with ground truth:
//   images/XXXXXXXX.png          rendered RGB
//   cams/XXXXXXXX_cam.txt        extrinsic, intrinsic, "DEPTH_MIN DEPTH_INTERVAL 128 DEPTH_MAX"
//   pair.txt                     neighbours ranked by MVSNet's view-selection score
//   depth_gt/XXXXXXXX.pfm        z-depth, 0 where nothing is hit (+ XXXXXXXX.png false-colour preview)
//   masks/XXXXXXXX.png           255 where the ground truth is valid
//   gt.ply                       surface points seen by some view (when the scene has a cloud)
//   scene.txt                    the generator settings (to regenerate the folder), with the
//                                photographic texture folders used (`texture_folders`)
// Every file is written atomically.
#pragma once

#include <string>
#include <vector>

#include "unsup_mvs/core/synth.h"

namespace umvs {

void write_synthetic_scene(const std::string& dir, const SynthScene& scene, const SynthConfig& config,
                           const std::vector<std::string>& texture_folders = {});

}  // namespace umvs
