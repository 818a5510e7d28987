// Solid textures, materials and primitives of the synthetic scenes: noise, albedo, ray
// intersection, containment and surface sampling.
#include <cmath>

#include "synth_scene.h"

namespace umvs {
namespace synth {

// ----------------------------------------------------------------------------------------------
// Solid textures: value noise on an integer lattice, summed over octaves (fractal Brownian motion).

double lattice_value(int64_t x, int64_t y, int64_t z, uint64_t seed) {
  uint64_t h = seed;
  h = mix64(h ^ static_cast<uint64_t>(x) * 0x9e3779b97f4a7c15ULL);
  h = mix64(h ^ static_cast<uint64_t>(y) * 0xc2b2ae3d27d4eb4fULL);
  h = mix64(h ^ static_cast<uint64_t>(z) * 0x165667b19e3779f9ULL);
  return to_unit(h);
}

double value_noise(const Vec3& p, uint64_t seed) {
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const int64_t ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy), iz = static_cast<int64_t>(fz);
  auto smooth = [](double t) { return t * t * (3.0 - 2.0 * t); };
  const double tx = smooth(p.x() - fx), ty = smooth(p.y() - fy), tz = smooth(p.z() - fz);
  double c[2][2][2];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int d = 0; d < 2; ++d) c[a][b][d] = lattice_value(ix + a, iy + b, iz + d, seed);
  auto lerp = [](double u, double v, double t) { return u + (v - u) * t; };
  const double x00 = lerp(c[0][0][0], c[1][0][0], tx), x10 = lerp(c[0][1][0], c[1][1][0], tx);
  const double x01 = lerp(c[0][0][1], c[1][0][1], tx), x11 = lerp(c[0][1][1], c[1][1][1], tx);
  return lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz);
}

// In [0,1], mean 0.5. `p` is in units of the largest feature.
double fbm(const Vec3& p, uint64_t seed, int octaves) {
  double sum = 0.0, norm = 0.0, amp = 1.0, freq = 1.0;
  for (int o = 0; o < octaves; ++o) {
    // A fixed rotation-like offset per octave avoids lattice-aligned artefacts.
    sum += amp * value_noise(p * freq + Vec3(17.3 * o, 5.1 * o, 11.7 * o), seed + 101 * o);
    norm += amp;
    amp *= 0.55;
    freq *= 2.03;
  }
  return sum / norm;
}



// Albedo at surface point `q` (primitive-local coordinates) whose in-surface axes are `ua`, `va`.
// `photo`: the photograph's colour there when the material wears one (instead of the noise).
Vec3 albedo(const Material& m, const Vec3& q, int ua, int va, double strength_scale, const Vec3* photo) {
  const double s = std::clamp(m.strength * strength_scale, 0.0, 2.0);
  const double n = photo ? 0.5 : fbm(q / m.scale, m.seed, m.octaves);
  const double c = std::clamp(0.5 + 2.6 * (n - 0.5) * s, 0.0, 1.0);
  Vec3 col = photo ? *photo : Vec3(m.color_a + (m.color_b - m.color_a) * c);
  const double u = q[ua], v = q[va];
  auto frac = [](double x) { return x - std::floor(x); };
  switch (m.pattern) {
    case Pattern::kNoise:
      break;
    case Pattern::kTiles: {
      const double cu = std::floor(u / m.period_u), cv = std::floor(v / m.period_v);
      const double tint = lattice_value(static_cast<int64_t>(cu), static_cast<int64_t>(cv), 7, m.seed) - 0.5;
      col *= 1.0 + 0.35 * tint * std::min(s, 1.0);
      const double gu = frac(u / m.period_u) * m.period_u, gv = frac(v / m.period_v) * m.period_v;
      const double grout = 0.04 * std::min(m.period_u, m.period_v);
      if (gu < grout || gv < grout) col += (m.accent - col) * std::min(s, 1.0);
      break;
    }
    case Pattern::kWindows: {
      const double fu = frac(u / m.period_u), fv = frac(v / m.period_v);
      if (fu > 0.25 && fu < 0.75 && fv > 0.3 && fv < 0.8) {
        const double sheen = fbm(q / (0.3 * m.scale), m.seed + 7, 3);
        col += (m.accent * (0.7 + 0.6 * sheen) - col) * std::min(s, 1.0);
      }
      break;
    }
    case Pattern::kWood: {
      if (photo) break;  // the photograph has its own grain
      const double ring = 0.5 + 0.5 * std::sin(2.0 * kPi * (u / m.period_u + 3.0 * (n - 0.5)));
      col *= 1.0 + 0.3 * (ring - 0.5) * std::min(s, 1.0);
      break;
    }
  }
  return col.cwiseMax(0.0).cwiseMin(1.0);
}

Primitive make(Shape shape, const Vec3& center, const Vec3& half, const Material& m, double yaw) {
  Primitive p;
  p.shape = shape;
  p.center = center;
  p.half = half;
  p.material = m;
  p.R = Eigen::AngleAxisd(yaw, Vec3::UnitZ()).toRotationMatrix();
  switch (shape) {
    case Shape::kRect: p.bound = Eigen::Vector2d(half.x(), half.y()).norm(); break;
    case Shape::kBox: p.bound = half.norm(); break;
    case Shape::kSphere: p.bound = half.x(); break;
    case Shape::kCylinder: p.bound = Eigen::Vector2d(half.x(), half.z()).norm(); break;
  }
  return p;
}
// A rectangle with normal `normal` (world), in-plane axis `u_axis`, half sizes (hu, hv).
Primitive make_rect(const Vec3& center, const Vec3& normal, const Vec3& u_axis, double hu, double hv, const Material& m) {
  Primitive p = make(Shape::kRect, center, Vec3(hu, hv, 0.0), m);
  const Vec3 n = normal.normalized(), u = u_axis.normalized();
  p.R.col(0) = u;
  p.R.col(1) = n.cross(u);
  p.R.col(2) = n;
  return p;
}

// Nearest intersection with t in (t_min, hit->t); updates *hit and returns true when found.
bool intersect(const Primitive& p, const Vec3& o_world, const Vec3& d_world, double t_min, Hit* hit) {
  const Vec3 oc = o_world - p.center;
  // Bounding sphere rejection.
  const double b_proj = oc.dot(d_world);
  const double dist2 = oc.squaredNorm() - b_proj * b_proj;
  if (dist2 > p.bound * p.bound * 1.0001 + 1e-12) return false;
  const Vec3 o = p.R.transpose() * oc, d = p.R.transpose() * d_world;
  double best = hit->t;
  Vec3 n_best;
  bool found = false;
  auto consider = [&](double t, const Vec3& n) {
    if (t > t_min && t < best) {
      best = t;
      n_best = n;
      found = true;
    }
  };
  const Vec3& h = p.half;
  switch (p.shape) {
    case Shape::kRect: {
      if (std::abs(d.z()) < 1e-15) return false;
      const double t = -o.z() / d.z();
      const Vec3 q = o + t * d;
      if (std::abs(q.x()) <= h.x() && std::abs(q.y()) <= h.y()) consider(t, Vec3::UnitZ());
      break;
    }
    case Shape::kBox: {
      double t_near = -kInf, t_far = kInf;
      int ax_near = 0, ax_far = 0;
      for (int i = 0; i < 3; ++i) {
        if (std::abs(d[i]) < 1e-15) {
          if (std::abs(o[i]) > h[i]) return false;
          continue;
        }
        double t1 = (-h[i] - o[i]) / d[i], t2 = (h[i] - o[i]) / d[i];
        if (t1 > t2) std::swap(t1, t2);
        if (t1 > t_near) { t_near = t1; ax_near = i; }
        if (t2 < t_far) { t_far = t2; ax_far = i; }
      }
      if (t_near > t_far) return false;
      const double t = t_near > t_min ? t_near : t_far;
      const int ax = t_near > t_min ? ax_near : ax_far;
      Vec3 n = Vec3::Zero();
      n[ax] = (o[ax] + t * d[ax]) > 0 ? 1.0 : -1.0;
      consider(t, n);
      break;
    }
    case Shape::kSphere: {
      const double r = h.x();
      const double b = o.dot(d), c = o.squaredNorm() - r * r;
      const double disc = b * b - c;
      if (disc < 0) return false;
      const double sq = std::sqrt(disc);
      for (double t : {-b - sq, -b + sq}) {
        if (t > t_min && t < best) {
          consider(t, (o + t * d) / r);
          break;
        }
      }
      break;
    }
    case Shape::kCylinder: {
      const double r = h.x(), hz = h.z();
      const double a = d.x() * d.x() + d.y() * d.y();
      if (a > 1e-18) {
        const double b = o.x() * d.x() + o.y() * d.y();
        const double c = o.x() * o.x() + o.y() * o.y() - r * r;
        const double disc = b * b - a * c;
        if (disc >= 0) {
          const double sq = std::sqrt(disc);
          for (double t : {(-b - sq) / a, (-b + sq) / a}) {
            const Vec3 q = o + t * d;
            if (std::abs(q.z()) <= hz) consider(t, Vec3(q.x() / r, q.y() / r, 0.0));
          }
        }
      }
      if (std::abs(d.z()) > 1e-15) {
        for (double zc : {-hz, hz}) {
          const double t = (zc - o.z()) / d.z();
          const Vec3 q = o + t * d;
          if (q.x() * q.x() + q.y() * q.y() <= r * r) consider(t, Vec3(0, 0, zc > 0 ? 1.0 : -1.0));
        }
      }
      break;
    }
  }
  if (!found) return false;
  hit->t = best;
  hit->normal_local = n_best;
  hit->local = o + best * d;
  return true;
}

bool contains(const Primitive& p, const Vec3& x_world, double margin) {
  const Vec3 q = p.R.transpose() * (x_world - p.center);
  const Vec3& h = p.half;
  switch (p.shape) {
    case Shape::kRect: return false;
    case Shape::kBox: return (q.cwiseAbs() - h).maxCoeff() < margin;
    case Shape::kSphere: return q.norm() < h.x() + margin;
    case Shape::kCylinder: return std::hypot(q.x(), q.y()) < h.x() + margin && std::abs(q.z()) < h.z() + margin;
  }
  return false;
}

// The two local axes spanning the surface at a hit (for tiles and windows): the ones where the
// local normal is smallest; for curved surfaces any pair works since those use noise.
void surface_axes(const Vec3& n_local, int* ua, int* va) {
  const Vec3 a = n_local.cwiseAbs();
  int axis_n = 0;
  a.maxCoeff(&axis_n);
  if (axis_n == 2) { *ua = 0; *va = 1; }
  else if (axis_n == 1) { *ua = 0; *va = 2; }
  else { *ua = 1; *va = 2; }
}


// ----------------------------------------------------------------------------------------------
// Ground-truth cloud: area-uniform samples on every surface, kept when a view sees them.

double surface_area(const Primitive& p) {
  const Vec3& h = p.half;
  switch (p.shape) {
    case Shape::kRect: return 4.0 * h.x() * h.y();
    case Shape::kBox: return 8.0 * (h.x() * h.y() + h.y() * h.z() + h.x() * h.z());
    case Shape::kSphere: return 4.0 * kPi * h.x() * h.x();
    case Shape::kCylinder: return 4.0 * kPi * h.x() * h.z() + 2.0 * kPi * h.x() * h.x();
  }
  return 0.0;
}

// A uniform point on the surface (local coordinates) and its local normal; u[0..2] uniform in [0,1).
void sample_surface(const Primitive& p, const double u[3], Vec3* q, Vec3* n) {
  const Vec3& h = p.half;
  switch (p.shape) {
    case Shape::kRect:
      *q = Vec3((2 * u[0] - 1) * h.x(), (2 * u[1] - 1) * h.y(), 0.0);
      *n = Vec3::UnitZ();
      return;
    case Shape::kBox: {
      const double a[3] = {h.y() * h.z(), h.x() * h.z(), h.x() * h.y()};  // face areas by normal axis
      double pick = u[2] * (a[0] + a[1] + a[2]);
      int axis = 0;
      while (axis < 2 && pick >= a[axis]) pick -= a[axis++];
      const double side = (pick / a[axis]) < 0.5 ? -1.0 : 1.0;
      const int i = (axis + 1) % 3, j = (axis + 2) % 3;
      *q = Vec3::Zero();
      (*q)[axis] = side * h[axis];
      (*q)[i] = (2 * u[0] - 1) * h[i];
      (*q)[j] = (2 * u[1] - 1) * h[j];
      *n = Vec3::Zero();
      (*n)[axis] = side;
      return;
    }
    case Shape::kSphere: {
      const double z = 2 * u[0] - 1, phi = 2 * kPi * u[1], r = std::sqrt(std::max(0.0, 1 - z * z));
      *n = Vec3(r * std::cos(phi), r * std::sin(phi), z);
      *q = *n * h.x();
      return;
    }
    case Shape::kCylinder: {
      const double side_area = 4.0 * kPi * h.x() * h.z(), cap_area = 2.0 * kPi * h.x() * h.x();
      const double phi = 2 * kPi * u[1];
      if (u[2] * (side_area + cap_area) < side_area) {
        *n = Vec3(std::cos(phi), std::sin(phi), 0.0);
        *q = Vec3(h.x() * n->x(), h.x() * n->y(), (2 * u[0] - 1) * h.z());
      } else {
        const double rr = h.x() * std::sqrt(u[0]);
        const double zc = (u[2] * (side_area + cap_area) - side_area) < cap_area / 2 ? -h.z() : h.z();
        *q = Vec3(rr * std::cos(phi), rr * std::sin(phi), zc);
        *n = Vec3(0, 0, zc > 0 ? 1.0 : -1.0);
      }
      return;
    }
  }
}

}  // namespace synth
}  // namespace umvs
