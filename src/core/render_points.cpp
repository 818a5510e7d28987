#include "unsup_mvs/core/render_points.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace umvs {

torch::Tensor render_points(const PointCloud& cloud, const Camera& camera, const RenderConfig& config) {
  const int W = camera.width, H = camera.height;
  if (W <= 0 || H <= 0) throw std::invalid_argument("render_points: camera has no image size");
  auto image = torch::empty({H, W, 3}, torch::kUInt8);
  for (int c = 0; c < 3; ++c) image.select(2, c).fill_(config.background[c]);
  std::vector<float> zbuf(static_cast<size_t>(W) * H, std::numeric_limits<float>::infinity());
  uint8_t* px = image.data_ptr<uint8_t>();
  const Eigen::Matrix3d KR = camera.K * camera.R();
  const Eigen::Vector3d Kt = camera.K * camera.t();
  const int r = std::max(0, config.splat_radius);
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d p = KR * cloud.points[i].cast<double>() + Kt;
    if (!(p.z() > 0)) continue;
    const int u = static_cast<int>(std::lround(p.x() / p.z())), v = static_cast<int>(std::lround(p.y() / p.z()));
    const float z = static_cast<float>(p.z());
    const std::array<uint8_t, 3> color = cloud.has_colors() ? cloud.colors[i] : std::array<uint8_t, 3>{160, 160, 160};
    for (int y = std::max(0, v - r); y <= std::min(H - 1, v + r); ++y) {
      for (int x = std::max(0, u - r); x <= std::min(W - 1, u + r); ++x) {
        const size_t k = static_cast<size_t>(y) * W + x;
        if (z >= zbuf[k]) continue;
        zbuf[k] = z;
        std::copy(color.begin(), color.end(), px + 3 * k);
      }
    }
  }
  return image;
}

Camera orbit_camera(const PointCloud& cloud, int width, int height, double azimuth_deg, double elevation_deg,
                    const Eigen::Vector3d& up_axis, double fov_deg) {
  if (cloud.empty()) throw std::invalid_argument("orbit_camera: empty cloud");
  if (width <= 0 || height <= 0 || !(fov_deg > 0 && fov_deg < 180)) throw std::invalid_argument("orbit_camera: bad size or field of view");
  // Median centre and 95th-percentile radius: robust to a few stray points.
  Eigen::Vector3d centre;
  for (int a = 0; a < 3; ++a) {
    std::vector<float> v;
    v.reserve(cloud.size());
    for (const auto& p : cloud.points) v.push_back(p[a]);
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    centre[a] = v[v.size() / 2];
  }
  std::vector<double> dist;
  dist.reserve(cloud.size());
  for (const auto& p : cloud.points) dist.push_back((p.cast<double>() - centre).norm());
  std::nth_element(dist.begin(), dist.begin() + dist.size() * 95 / 100, dist.end());
  const double radius = std::max(1e-6, dist[dist.size() * 95 / 100]);

  const Eigen::Vector3d up = up_axis.normalized();
  // Any unit vector orthogonal to up defines azimuth 0.
  Eigen::Vector3d e0 = up.unitOrthogonal();
  const Eigen::Vector3d e1 = up.cross(e0);
  const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
  const Eigen::Vector3d dir = std::cos(el) * (std::cos(az) * e0 + std::sin(az) * e1) + std::sin(el) * up;
  const double f = 0.5 * width / std::tan(0.5 * fov_deg * M_PI / 180.0);
  const double distance = radius * f / (0.5 * std::min(width, height)) * 1.05;
  const Eigen::Vector3d eye = centre + distance * dir;
  Eigen::Matrix3d K;
  K << f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1;
  return Camera::look_at(eye, centre, K, width, height, up);
}

}  // namespace umvs
