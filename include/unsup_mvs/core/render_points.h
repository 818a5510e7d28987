// A small z-buffered point splatter, to look at fused clouds without a viewer (docs pictures,
// quick checks over ssh). Eigen + LibTorch tensors for the image.
#pragma once

#include <torch/types.h>

#include <array>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

struct RenderConfig {
  int splat_radius = 1;                         // each point covers (2r+1)^2 pixels
  std::array<uint8_t, 3> background{255, 255, 255};
};

// The cloud seen by `camera` (camera.width x camera.height): nearest point wins per pixel.
// Points without colours are drawn grey. -> uint8 [H,W,3]
torch::Tensor render_points(const PointCloud& cloud, const Camera& camera, const RenderConfig& config = {});

// A camera of the given size looking at the cloud's centre (median) from azimuth/elevation
// (degrees) about `up`, far enough back for a `fov_deg` horizontal field of view to frame 95% of
// the points. Throws std::invalid_argument for an empty cloud.
Camera orbit_camera(const PointCloud& cloud, int width, int height, double azimuth_deg, double elevation_deg,
                    const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ(), double fov_deg = 40.0);

}  // namespace umvs
