#include "unsup_mvs/core/synth_textures.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {
namespace {

// Mirrored repeat: ... 2 1 0 | 0 1 2 ... w-1 | w-1 w-2 ...
int mirror(int i, int w) {
  const int period = 2 * w;
  i %= period;
  if (i < 0) i += period;
  return i < w ? i : period - 1 - i;
}

}  // namespace

PhotoTextureBank::PhotoTextureBank(const std::vector<torch::Tensor>& images) {
  for (size_t k = 0; k < images.size(); ++k) {
    const torch::Tensor& img = images[k];
    if (!img.defined() || img.dim() != 3 || img.size(2) != 3 || img.scalar_type() != torch::kUInt8 ||
        img.size(0) < 2 || img.size(1) < 2) {
      throw std::invalid_argument("photo texture " + std::to_string(k) +
                                  ": expected a uint8 [H,W,3] image of at least 2x2 pixels");
    }
    const torch::Tensor c = img.contiguous();
    Level base;
    base.height = static_cast<int>(c.size(0));
    base.width = static_cast<int>(c.size(1));
    base.rgb.resize(static_cast<size_t>(base.width) * base.height * 3);
    const uint8_t* src = c.data_ptr<uint8_t>();
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < base.rgb.size(); ++i) {
      base.rgb[i] = src[i] / 255.0f;
      sum[i % 3] += base.rgb[i];
    }
    means_.push_back(sum / (static_cast<double>(base.width) * base.height));
    std::vector<Level> pyramid{std::move(base)};
    // Halve (2x2 box filter) down to one texel.
    while (std::max(pyramid.back().width, pyramid.back().height) > 1) {
      const Level& f = pyramid.back();
      Level h;
      h.width = std::max(1, f.width / 2);
      h.height = std::max(1, f.height / 2);
      h.rgb.resize(static_cast<size_t>(h.width) * h.height * 3);
      for (int y = 0; y < h.height; ++y) {
        for (int x = 0; x < h.width; ++x) {
          for (int ch = 0; ch < 3; ++ch) {
            float s = 0.0f;
            for (int dy = 0; dy < 2; ++dy)
              for (int dx = 0; dx < 2; ++dx) {
                const int sx = std::min(2 * x + dx, f.width - 1), sy = std::min(2 * y + dy, f.height - 1);
                s += f.rgb[(static_cast<size_t>(sy) * f.width + sx) * 3 + ch];
              }
            h.rgb[(static_cast<size_t>(y) * h.width + x) * 3 + ch] = 0.25f * s;
          }
        }
      }
      pyramid.push_back(std::move(h));
    }
    pyramids_.push_back(std::move(pyramid));
  }
}

Eigen::Vector3d PhotoTextureBank::texel(int texture, int level, double x, double y) const {
  const std::vector<Level>& pyr = pyramids_.at(texture);
  const Level& base = pyr.front();
  const Level& l = pyr.at(level);
  // Same normalised position on every level: texel centres sit at (i + 0.5) / width.
  const double xl = (x + 0.5) * l.width / base.width - 0.5, yl = (y + 0.5) * l.height / base.height - 0.5;
  const double fx = std::floor(xl), fy = std::floor(yl);
  const double tx = xl - fx, ty = yl - fy;
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  for (int dy = 0; dy < 2; ++dy) {
    for (int dx = 0; dx < 2; ++dx) {
      const double w = (dx ? tx : 1.0 - tx) * (dy ? ty : 1.0 - ty);
      if (w == 0.0) continue;
      const float* px = &l.rgb[(static_cast<size_t>(mirror(y0 + dy, l.height)) * l.width + mirror(x0 + dx, l.width)) * 3];
      out += w * Eigen::Vector3d(px[0], px[1], px[2]);
    }
  }
  return out;
}

Eigen::Vector3d PhotoTextureBank::planar(const PhotoMapping& m, double a, double b, double footprint) const {
  const double ca = std::cos(m.angle), sa = std::sin(m.angle);
  const int w0 = pyramids_.at(m.texture).front().width;
  // In image widths, then in level-0 texels.
  const double u = (ca * a - sa * b) / m.size + m.offset.x(), v = (sa * a + ca * b) / m.size + m.offset.y();
  const double x = u * w0 - 0.5, y = v * w0 - 0.5;
  const int top = levels(m.texture) - 1;
  const double texel_size = m.size / w0;
  const double level = footprint > texel_size ? std::min<double>(top, std::log2(footprint / texel_size)) : 0.0;
  const int l0 = static_cast<int>(std::floor(level));
  const double t = level - l0;
  Eigen::Vector3d c = texel(m.texture, l0, x, y);
  if (t > 0.0 && l0 < top) c = (1.0 - t) * c + t * texel(m.texture, l0 + 1, x, y);
  return c;
}

Eigen::Vector3d PhotoTextureBank::sample(const PhotoMapping& m, const Eigen::Vector3d& q, const Eigen::Vector3d& n,
                                         double footprint) const {
  // Triplanar weights: a flat face (axis-aligned local normal) uses exactly one plane.
  Eigen::Vector3d w;
  for (int k = 0; k < 3; ++k) w[k] = std::pow(std::max(0.0, std::abs(n[k]) - 0.3), 3.0);
  w /= w.sum();
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    if (w[k] <= 0.0) continue;
    c += w[k] * planar(m, q[(k + 1) % 3], q[(k + 2) % 3], footprint);
  }
  return c.cwiseProduct(m.tint).cwiseMax(0.0).cwiseMin(1.0);
}

}  // namespace umvs
