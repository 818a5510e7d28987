#include "unsup_mvs/core/synth.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "unsup_mvs/core/synth_textures.h"
#include "unsup_mvs/core/view_selection.h"

namespace umvs {
namespace {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kInf = std::numeric_limits<double>::infinity();

double deg2rad(double d) { return d * kPi / 180.0; }

// ----------------------------------------------------------------------------------------------
// Deterministic randomness (no std distributions: their output differs between libraries).

uint64_t mix64(uint64_t x) {  // splitmix64 finaliser
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
double to_unit(uint64_t h) { return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0); }

class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(mix64(seed ^ 0x5851f42d4c957f2dULL)) {}
  double uniform() {
    state_ += 0x9e3779b97f4a7c15ULL;
    return to_unit(mix64(state_));
  }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  int integer(int lo, int hi) {  // [lo, hi]
    return std::min(hi, lo + static_cast<int>(uniform() * (hi - lo + 1)));
  }
  uint64_t bits() {
    state_ += 0x9e3779b97f4a7c15ULL;
    return mix64(state_);
  }

 private:
  uint64_t state_;
};

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

enum class Pattern { kNoise, kTiles, kWindows, kWood };

struct Material {
  Vec3 color_a{0.3, 0.3, 0.3}, color_b{0.8, 0.8, 0.8};  // albedo range of the noise
  double scale = 0.1;       // largest noise feature (scene units)
  int octaves = 5;
  double strength = 1.0;    // contrast (scaled by SynthConfig::texture_strength)
  Pattern pattern = Pattern::kNoise;
  double period_u = 0.5, period_v = 0.5;  // tiles / windows (in-surface coordinates)
  Vec3 accent{0.1, 0.12, 0.18};           // grout or window-glass colour
  double specular = 0.0;    // Blinn-Phong weight when specular highlights are on
  uint64_t seed = 0;
  PhotoMapping photo;       // photo.texture >= 0: a photograph replaces the noise
};

// Albedo at surface point `q` (primitive-local coordinates) whose in-surface axes are `ua`, `va`.
// `photo`: the photograph's colour there when the material wears one (instead of the noise).
Vec3 albedo(const Material& m, const Vec3& q, int ua, int va, double strength_scale, const Vec3* photo = nullptr) {
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

// ----------------------------------------------------------------------------------------------
// Primitives, intersected in their local frame (world = R * local + center).

enum class Shape { kRect, kBox, kSphere, kCylinder };

struct Primitive {
  Shape shape = Shape::kRect;
  Vec3 center = Vec3::Zero();
  Mat3 R = Mat3::Identity();  // columns: local axes in world coordinates
  // kRect: half sizes along local x, y (normal local z); kBox: half sizes; kSphere: radius in x;
  // kCylinder: radius in x, half height in z (axis local z).
  Vec3 half = Vec3::Ones();
  Material material;
  double bound = 0.0;  // bounding-sphere radius
};

Primitive make(Shape shape, const Vec3& center, const Vec3& half, const Material& m, double yaw = 0.0) {
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

struct Hit {
  double t = kInf;
  int prim = -1;
  Vec3 normal_local = Vec3::UnitZ();
  Vec3 local = Vec3::Zero();
};

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

enum class Background { kBlack, kSky };

struct CameraPlan {
  double focal = 0.9;  // fx = fy = focal * width
  // Orbit: eyes on a circle arc around `center` looking at it.
  Vec3 orbit_center = Vec3::Zero();
  double orbit_radius = 1.0, orbit_elevation_deg = 30.0, orbit_elevation_jitter_deg = 0.0;
  double orbit_azimuth_deg = -90.0, orbit_span_deg = 90.0;
  // Forward: eyes from path_start to path_end, heading along the path turned by yaw_offset.
  Vec3 path_start = Vec3::Zero(), path_end = Vec3::UnitX();
  double path_yaw_offset_deg = 0.0, path_pitch_deg = 0.0, path_yaw_wobble_deg = 8.0;
  // Random: eyes uniform in a box, looking at a point uniform in another box.
  Vec3 random_eye_min = Vec3::Zero(), random_eye_max = Vec3::Ones();
  Vec3 random_target_min = Vec3::Zero(), random_target_max = Vec3::Ones();
  double clearance = 0.1;  // random eyes keep this distance from every solid
  // Drive / turn (a ground robot): the eye at a height drawn in [height_min, height_max], starting
  // near robot_start (x, y) facing robot_heading_deg (+- 10 degrees). Drive: steps of about
  // robot_step (at most robot_max_travel in all) along the heading, which turns slowly; the eye
  // stays inside [robot_bounds_min, robot_bounds_max] (x, y) and clear of every solid. Turn: the
  // heading sweeps 60-120 degrees with the eye robot_arm in front of a fixed vertical axis.
  Vec3 robot_start = Vec3::Zero();
  double robot_heading_deg = 0.0, robot_pitch_deg = 0.0;
  double robot_height_min = 0.3, robot_height_max = 1.5;
  double robot_step = 0.1, robot_max_travel = 2.0, robot_turn_deg_per_step = 2.0, robot_arm = 0.2;
  Vec3 robot_bounds_min = Vec3::Constant(-1e9), robot_bounds_max = Vec3::Constant(1e9);
};

struct LightPlan {
  Vec3 base = Vec3(0, 0, 10);  // light position without lighting change
  Vec3 pivot = Vec3::Zero();   // the light turns about the vertical axis through this point
  double ambient = 0.35;
};

struct SceneDef {
  std::vector<Primitive> prims;
  Background background = Background::kBlack;
  CameraPlan cameras;
  LightPlan light;
  SynthTrajectory natural = SynthTrajectory::kOrbit;
};

Material random_material(Rng& rng, double scale, double strength = 1.0) {
  Material m;
  const Vec3 base(rng.uniform(0.2, 0.85), rng.uniform(0.2, 0.85), rng.uniform(0.2, 0.85));
  m.color_a = base * 0.35;
  m.color_b = (base * 1.25).cwiseMin(1.0);
  m.scale = scale;
  m.strength = strength;
  m.seed = rng.bits();
  return m;
}

// ----------------------------------------------------------------------------------------------
// Scenes.

SceneDef dtu_like_scene(Rng& rng) {
  SceneDef s;
  Material table;
  table.color_a = Vec3(0.35, 0.2, 0.1);
  table.color_b = Vec3(0.8, 0.6, 0.4);
  table.pattern = Pattern::kWood;
  table.period_u = 0.03;
  table.scale = 0.06;
  table.seed = rng.bits();
  s.prims.push_back(make(Shape::kRect, Vec3(0, 0, 0), Vec3(0.32, 0.32, 0), table));
  // The "statue": a textured column with a ball on top.
  const double col_h = rng.uniform(0.07, 0.1), col_r = rng.uniform(0.045, 0.06);
  Material column = random_material(rng, 0.03);
  column.specular = 0.6;
  s.prims.push_back(make(Shape::kCylinder, Vec3(0, 0, col_h), Vec3(col_r, col_r, col_h), column));
  const double ball_r = rng.uniform(0.04, 0.055);
  Material ball = random_material(rng, 0.02);
  ball.specular = 0.8;
  s.prims.push_back(make(Shape::kSphere, Vec3(0, 0, 2 * col_h + ball_r * 0.9), Vec3::Constant(ball_r), ball));
  // Objects around it; one of them almost textureless.
  const int n = rng.integer(5, 7);
  const int weak = rng.integer(0, n - 1);
  for (int i = 0; i < n; ++i) {
    const double ang = 2.0 * kPi * (i + rng.uniform(0.0, 0.6)) / n, rad = rng.uniform(0.1, 0.2);
    const Vec3 at(rad * std::cos(ang), rad * std::sin(ang), 0.0);
    Material m = random_material(rng, rng.uniform(0.015, 0.05), i == weak ? 0.04 : 1.0);
    if (rng.uniform() < 0.3) {
      m.pattern = Pattern::kTiles;
      m.period_u = m.period_v = rng.uniform(0.012, 0.025);
      m.accent = m.color_a * 0.5;
    }
    m.specular = rng.uniform(0.0, 0.7);
    switch (rng.integer(0, 2)) {
      case 0: {
        const Vec3 half(rng.uniform(0.02, 0.05), rng.uniform(0.02, 0.05), rng.uniform(0.02, 0.06));
        s.prims.push_back(make(Shape::kBox, at + Vec3(0, 0, half.z()), half, m, rng.uniform(0, kPi)));
        break;
      }
      case 1: {
        const double r = rng.uniform(0.02, 0.045);
        s.prims.push_back(make(Shape::kSphere, at + Vec3(0, 0, r), Vec3::Constant(r), m));
        break;
      }
      default: {
        const double r = rng.uniform(0.015, 0.035), hz = rng.uniform(0.02, 0.07);
        s.prims.push_back(make(Shape::kCylinder, at + Vec3(0, 0, hz), Vec3(r, r, hz), m));
        break;
      }
    }
  }
  s.background = Background::kBlack;
  CameraPlan& c = s.cameras;
  c.focal = 1.1;
  c.orbit_center = Vec3(0, 0, 0.06);
  c.orbit_radius = 0.6;
  c.orbit_elevation_deg = 30.0;
  c.orbit_elevation_jitter_deg = 8.0;
  c.orbit_azimuth_deg = -90.0;
  c.orbit_span_deg = 100.0;
  c.random_eye_min = Vec3(-0.45, -0.65, 0.25);
  c.random_eye_max = Vec3(0.45, -0.35, 0.5);
  c.random_target_min = Vec3(-0.05, -0.05, 0.02);
  c.random_target_max = Vec3(0.05, 0.05, 0.12);
  c.clearance = 0.03;
  c.path_start = Vec3(-0.3, -0.55, 0.35);
  c.path_end = Vec3(0.3, -0.55, 0.35);
  c.path_yaw_offset_deg = 90.0;  // looking at the table while sliding past it
  c.path_pitch_deg = -30.0;
  c.path_yaw_wobble_deg = 3.0;
  // A small robot approaching the table (table-top scale, like the rest of this scene).
  c.robot_start = Vec3(0.0, -0.62, 0.0);
  c.robot_heading_deg = 90.0;
  c.robot_pitch_deg = -22.0;
  c.robot_height_min = 0.12;
  c.robot_height_max = 0.3;
  c.robot_step = 0.012;
  c.robot_max_travel = 0.22;
  c.robot_turn_deg_per_step = 1.0;
  c.robot_arm = 0.04;
  c.robot_bounds_min = Vec3(-0.5, -0.8, 0.0);
  c.robot_bounds_max = Vec3(0.5, -0.35, 0.0);
  s.light.base = Vec3(0.3, -0.6, 0.9);
  s.light.pivot = Vec3::Zero();
  s.natural = SynthTrajectory::kOrbit;
  return s;
}

// More furniture for the room: chairs at the table, a bookshelf with books, a floor lamp, a rug
// and a wall-mounted television (dark, glossy and textureless), all off the robot's lane
// (y in [-1.1, -0.2]). Drawn after the rest of the layout.
void add_room_furniture(SceneDef* s, Rng& rng, double X, double Y, const Vec3& table_c, double pillar_x) {
  auto& prims = s->prims;
  Material chair_m = random_material(rng, rng.uniform(0.04, 0.1));
  for (int side : {-1, 1}) {
    const Vec3 seat = table_c + Vec3(side * 0.85, rng.uniform(-0.1, 0.1), -0.3);  // seat at 0.45 m
    prims.push_back(make(Shape::kBox, seat, Vec3(0.22, 0.22, 0.02), chair_m));
    for (int lx : {-1, 1})
      for (int ly : {-1, 1})
        prims.push_back(make(Shape::kCylinder, seat + Vec3(lx * 0.19, ly * 0.19, -0.235), Vec3(0.015, 0.015, 0.215), chair_m));
    prims.push_back(make(Shape::kBox, seat + Vec3(side * 0.2, 0, 0.25), Vec3(0.02, 0.22, 0.23), chair_m));
  }
  // Bookshelf against the -y wall, on the side away from the pillar; two rows of books.
  const double shelf_x = pillar_x > 0 ? rng.uniform(-2.2, -1.2) : rng.uniform(1.2, 2.2);
  Material shelf_m = random_material(rng, 0.15, 0.5);
  const double shelf_half_w = rng.uniform(0.4, 0.6);
  prims.push_back(make(Shape::kBox, Vec3(shelf_x, -Y + 0.16, 0.9), Vec3(shelf_half_w, 0.15, 0.9), shelf_m));
  for (double z : {0.55, 1.25}) {
    double x = shelf_x - shelf_half_w + 0.03;
    while (true) {
      const double w = rng.uniform(0.015, 0.04), h = rng.uniform(0.09, 0.15);
      if (x + 2 * w > shelf_x + shelf_half_w - 0.03) break;
      Material book = random_material(rng, 0.02, rng.uniform(0.1, 1.0));
      prims.push_back(make(Shape::kBox, Vec3(x + w, -Y + 0.33, z + h), Vec3(w, 0.03, h), book));
      x += 2 * w + rng.uniform(0.0, 0.05);
    }
  }
  // Floor lamp near the sofa, a rug under the table.
  Material metal = random_material(rng, 0.05, 0.1);
  metal.specular = 0.8;
  const Vec3 lamp(rng.uniform(-2.3, 2.3), 1.35, 0.0);
  prims.push_back(make(Shape::kCylinder, lamp + Vec3(0, 0, 0.75), Vec3(0.015, 0.015, 0.75), metal));
  Material shade = random_material(rng, 0.05, 0.3);
  prims.push_back(make(Shape::kCylinder, lamp + Vec3(0, 0, 1.55), Vec3(0.18, 0.18, 0.14), shade));
  Material rug = random_material(rng, rng.uniform(0.05, 0.15), 1.3);
  if (rng.uniform() < 0.5) {
    rug.pattern = Pattern::kTiles;
    rug.period_u = rug.period_v = rng.uniform(0.1, 0.3);
    rug.accent = rug.color_b * 0.5;
  }
  prims.push_back(make(Shape::kBox, Vec3(table_c.x(), table_c.y(), 0.004), Vec3(1.0, 0.6, 0.004), rug, rng.uniform(-0.2, 0.2)));
  Material screen;  // a switched-off television: textureless and specular
  screen.color_a = Vec3(0.03, 0.03, 0.035);
  screen.color_b = Vec3(0.06, 0.06, 0.07);
  screen.strength = 0.05;
  screen.specular = 0.9;
  screen.seed = rng.bits();
  prims.push_back(make_rect(Vec3(-X + 0.04, rng.uniform(-0.3, 1.2), 1.3), Vec3::UnitX(), -Vec3::UnitY(), 0.55, 0.32, screen));
}

SceneDef room_scene(Rng& rng) {
  SceneDef s;
  const double X = 3.0, Y = 2.5, Z = 2.6;
  Material floor;
  floor.color_a = Vec3(0.45, 0.4, 0.35);
  floor.color_b = Vec3(0.85, 0.8, 0.7);
  floor.pattern = Pattern::kTiles;
  floor.period_u = floor.period_v = 0.5;
  floor.accent = Vec3(0.25, 0.22, 0.2);
  floor.scale = 0.25;
  floor.seed = rng.bits();
  s.prims.push_back(make_rect(Vec3(0, 0, 0), Vec3::UnitZ(), Vec3::UnitX(), X, Y, floor));
  Material ceiling;  // weakly textured, as real ceilings
  ceiling.color_a = Vec3(0.8, 0.8, 0.78);
  ceiling.color_b = Vec3(0.95, 0.95, 0.93);
  ceiling.strength = 0.05;
  ceiling.scale = 0.5;
  ceiling.seed = rng.bits();
  s.prims.push_back(make_rect(Vec3(0, 0, Z), -Vec3::UnitZ(), Vec3::UnitX(), X, Y, ceiling));
  // Walls: inward normals; one plain painted wall (weak texture).
  const int plain = rng.integer(0, 3);
  const Vec3 wall_c[4] = {Vec3(X, 0, Z / 2), Vec3(-X, 0, Z / 2), Vec3(0, Y, Z / 2), Vec3(0, -Y, Z / 2)};
  const Vec3 wall_n[4] = {-Vec3::UnitX(), Vec3::UnitX(), -Vec3::UnitY(), Vec3::UnitY()};
  for (int i = 0; i < 4; ++i) {
    Material m = random_material(rng, rng.uniform(0.15, 0.6), i == plain ? 0.05 : 0.8);
    m.color_a = m.color_a * 0.5 + Vec3::Constant(0.35);
    m.color_b = m.color_b * 0.3 + Vec3::Constant(0.6);
    if (i != plain && rng.uniform() < 0.4) {
      m.pattern = Pattern::kWood;  // wallpaper stripes
      m.period_u = rng.uniform(0.08, 0.2);
    }
    const double half_len = i < 2 ? Y : X;
    s.prims.push_back(make_rect(wall_c[i], wall_n[i], Vec3::UnitZ().cross(wall_n[i]), half_len, Z / 2, m));
    // A picture or a door on most walls, a few centimetres in front of it.
    if (rng.uniform() < 0.8) {
      Material pic = random_material(rng, rng.uniform(0.03, 0.12), 1.3);
      const double w = rng.uniform(0.3, 0.8), h = rng.uniform(0.3, 0.6);
      const double off = rng.uniform(-half_len + 1.0, half_len - 1.0);
      const Vec3 along = Vec3::UnitZ().cross(wall_n[i]);
      const Vec3 c = wall_c[i] + along * off + Vec3(0, 0, rng.uniform(0.0, 0.5)) + wall_n[i] * 0.02;
      s.prims.push_back(make_rect(c, wall_n[i], along, w, h, pic));
    }
  }
  // Furniture along the walls, a table in the middle and a pillar.
  Material wood;
  wood.color_a = Vec3(0.3, 0.18, 0.08);
  wood.color_b = Vec3(0.7, 0.5, 0.3);
  wood.pattern = Pattern::kWood;
  wood.period_u = 0.05;
  wood.scale = 0.2;
  wood.seed = rng.bits();
  const Vec3 table_c(rng.uniform(-0.6, 0.6), rng.uniform(0.6, 1.1), 0.75);
  s.prims.push_back(make(Shape::kBox, table_c, Vec3(0.6, 0.4, 0.02), wood, rng.uniform(-0.2, 0.2)));
  for (int lx : {-1, 1})
    for (int ly : {-1, 1})
      s.prims.push_back(make(Shape::kCylinder, table_c + Vec3(lx * 0.5, ly * 0.3, -0.375 - 0.01), Vec3(0.03, 0.03, 0.365), wood));
  Material ball = random_material(rng, 0.05);
  ball.specular = 0.7;
  const double br = rng.uniform(0.08, 0.14);
  s.prims.push_back(make(Shape::kSphere, table_c + Vec3(rng.uniform(-0.3, 0.3), 0, 0.02 + br), Vec3::Constant(br), ball));
  const Vec3 box_half(rng.uniform(0.08, 0.15), rng.uniform(0.08, 0.15), rng.uniform(0.05, 0.12));
  s.prims.push_back(make(Shape::kBox, table_c + Vec3(rng.uniform(-0.4, 0.4), rng.uniform(-0.2, 0.2), 0.02 + box_half.z()),
                         box_half, random_material(rng, 0.04), rng.uniform(0, kPi)));
  // Sofa and cabinets along the +y / +-x walls.
  const Vec3 sofa_half(rng.uniform(0.8, 1.1), 0.45, 0.4);
  s.prims.push_back(make(Shape::kBox, Vec3(rng.uniform(-1.2, 1.2), Y - 0.46, 0.4), sofa_half, random_material(rng, 0.08)));
  for (int side : {-1, 1}) {
    const Vec3 cab_half(0.3, rng.uniform(0.4, 0.7), rng.uniform(0.5, 0.95));
    Material cab = random_material(rng, 0.1, side > 0 ? 1.0 : 0.06);  // one cabinet plain
    cab.pattern = side > 0 ? Pattern::kTiles : Pattern::kNoise;
    cab.period_u = cab.period_v = 0.3;
    cab.accent = cab.color_a * 0.4;
    s.prims.push_back(make(Shape::kBox, Vec3(side * (X - 0.31), rng.uniform(-1.2, 1.2), cab_half.z()), cab_half, cab));
  }
  Material pillar = random_material(rng, 0.3);
  s.prims.push_back(make(Shape::kCylinder, Vec3(rng.uniform(-1.5, 1.5), rng.uniform(-2.2, -1.7), Z / 2), Vec3(0.18, 0.18, Z / 2), pillar));
  const double pillar_x = s.prims.back().center.x();
  // Clutter on the floor (boxes and balls), away from the robot path at y ~ -0.6.
  const int n = rng.integer(3, 5);
  for (int i = 0; i < n; ++i) {
    const Vec3 at(rng.uniform(-2.4, 2.4), rng.uniform(0.2, 1.8), 0.0);
    Material m = random_material(rng, rng.uniform(0.03, 0.12));
    if (rng.uniform() < 0.5) {
      const Vec3 half(rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.35));
      s.prims.push_back(make(Shape::kBox, at + Vec3(0, 0, half.z()), half, m, rng.uniform(0, kPi)));
    } else {
      const double r = rng.uniform(0.1, 0.25);
      s.prims.push_back(make(Shape::kSphere, at + Vec3(0, 0, r), Vec3::Constant(r), m));
    }
  }
  add_room_furniture(&s, rng, X, Y, table_c, pillar_x);
  s.background = Background::kBlack;  // never seen: the room is closed
  CameraPlan& c = s.cameras;
  c.focal = 0.8;
  c.path_start = Vec3(-2.3, -0.7, 1.25);
  c.path_end = Vec3(1.7, -0.5, 1.25);
  c.path_yaw_offset_deg = 25.0;
  c.path_pitch_deg = -12.0;
  c.path_yaw_wobble_deg = 10.0;
  c.orbit_center = Vec3(0, 0.4, 0.8);
  c.orbit_radius = 1.9;
  c.orbit_elevation_deg = 15.0;
  c.orbit_elevation_jitter_deg = 4.0;
  c.orbit_azimuth_deg = -90.0;
  c.orbit_span_deg = 120.0;
  c.random_eye_min = Vec3(-2.0, -1.6, 0.9);
  c.random_eye_max = Vec3(2.0, 0.3, 1.8);
  c.random_target_min = Vec3(-X, -Y, 0.3);
  c.random_target_max = Vec3(X, Y, 1.6);
  c.clearance = 0.25;
  c.robot_start = Vec3(-2.1, -0.65, 0.0);
  c.robot_heading_deg = 0.0;
  c.robot_pitch_deg = -5.0;
  c.robot_step = 0.1;
  c.robot_max_travel = 3.6;
  c.robot_turn_deg_per_step = 2.0;
  c.robot_arm = 0.15;
  c.robot_bounds_min = Vec3(-2.35, -1.1, 0.0);
  c.robot_bounds_max = Vec3(2.35, -0.2, 0.0);
  s.light.base = Vec3(0.5, 0.0, Z - 0.2);
  s.light.pivot = Vec3(0.0, 0.0, Z - 0.2);
  s.light.ambient = 0.4;
  s.natural = SynthTrajectory::kForward;
  return s;
}

SceneDef facade_scene(Rng& rng) {
  SceneDef s;
  Material asphalt;
  asphalt.color_a = Vec3(0.2, 0.2, 0.22);
  asphalt.color_b = Vec3(0.45, 0.45, 0.47);
  asphalt.scale = 1.5;
  asphalt.strength = 0.5;
  asphalt.seed = rng.bits();
  s.prims.push_back(make(Shape::kRect, Vec3(0, 0, 0), Vec3(45, 30, 0), asphalt));
  Material pavement;
  pavement.color_a = Vec3(0.5, 0.48, 0.45);
  pavement.color_b = Vec3(0.8, 0.78, 0.74);
  pavement.pattern = Pattern::kTiles;
  pavement.period_u = pavement.period_v = 0.6;
  pavement.accent = Vec3(0.3, 0.3, 0.3);
  pavement.scale = 0.8;
  pavement.seed = rng.bits();
  s.prims.push_back(make(Shape::kBox, Vec3(0, 5.0, 0.075), Vec3(45, 2.0, 0.075), pavement));
  // Buildings along both sides of the street: facades at y = +7 and y = -9.
  for (int side : {1, -1}) {
    const double front = side > 0 ? 7.0 : -9.0;
    double x = -45.0;
    while (x < 45.0) {
      const double w = std::min(rng.uniform(8.0, 16.0), 45.0 - x);
      const double h = rng.uniform(8.0, 22.0);
      if (w > 1.0) {
        Material m = random_material(rng, rng.uniform(1.0, 3.0), rng.uniform() < 0.15 ? 0.08 : 0.9);
        m.color_a = m.color_a * 0.6 + Vec3::Constant(0.25);
        m.color_b = m.color_b * 0.5 + Vec3::Constant(0.45);
        m.pattern = Pattern::kWindows;
        m.period_u = rng.uniform(2.2, 3.5);
        m.period_v = rng.uniform(2.8, 3.4);
        m.accent = Vec3(rng.uniform(0.08, 0.2), rng.uniform(0.12, 0.25), rng.uniform(0.2, 0.35));
        m.specular = 0.3;
        s.prims.push_back(make(Shape::kBox, Vec3(x + w / 2, front + side * 5.0, h / 2), Vec3(w / 2 - 0.05, 5.0, h / 2), m));
      }
      x += w + (rng.uniform() < 0.2 ? rng.uniform(2.0, 5.0) : 0.0);
    }
  }
  // Trees on the pavement, parked cars at the kerb.
  for (double x = -40.0 + rng.uniform(0, 6); x < 40.0; x += rng.uniform(7.0, 12.0)) {
    Material bark = random_material(rng, 0.3);
    bark.color_a = Vec3(0.2, 0.14, 0.1);
    bark.color_b = Vec3(0.45, 0.35, 0.25);
    const double trunk_h = rng.uniform(2.5, 3.5);
    s.prims.push_back(make(Shape::kCylinder, Vec3(x, 5.5, trunk_h / 2), Vec3(0.18, 0.18, trunk_h / 2), bark));
    Material leaves;
    leaves.color_a = Vec3(0.08, 0.2, 0.05);
    leaves.color_b = Vec3(0.4, 0.65, 0.25);
    leaves.scale = 0.6;
    leaves.octaves = 6;
    leaves.seed = rng.bits();
    const double r = rng.uniform(1.3, 1.9);
    s.prims.push_back(make(Shape::kSphere, Vec3(x, 5.5, trunk_h + r * 0.7), Vec3::Constant(r), leaves));
  }
  for (double x = -35.0 + rng.uniform(0, 5); x < 35.0; x += rng.uniform(5.0, 14.0)) {
    Material car = random_material(rng, 0.5, 0.3);
    car.specular = 0.9;
    s.prims.push_back(make(Shape::kBox, Vec3(x, 2.2, 0.75), Vec3(2.1, 0.9, 0.6), car));
    Material glass = car;
    glass.color_a = Vec3(0.05, 0.07, 0.1);
    glass.color_b = Vec3(0.2, 0.25, 0.3);
    s.prims.push_back(make(Shape::kBox, Vec3(x - 0.2, 2.2, 1.6), Vec3(1.1, 0.8, 0.3), glass));
  }
  s.background = Background::kSky;
  CameraPlan& c = s.cameras;
  c.focal = 0.9;
  c.path_start = Vec3(-8, -2.0, 1.6);
  c.path_end = Vec3(8, -2.0, 1.6);
  c.path_yaw_offset_deg = 45.0;
  c.path_pitch_deg = 4.0;
  c.path_yaw_wobble_deg = 6.0;
  c.orbit_center = Vec3(0, 7.0, 5.0);
  c.orbit_radius = 15.0;
  c.orbit_elevation_deg = 8.0;
  c.orbit_elevation_jitter_deg = 3.0;
  c.orbit_azimuth_deg = -90.0;
  c.orbit_span_deg = 60.0;
  c.random_eye_min = Vec3(-10, -6, 1.2);
  c.random_eye_max = Vec3(10, 1.0, 3.0);
  c.random_target_min = Vec3(-20, 7.0, 1.0);
  c.random_target_max = Vec3(20, 7.5, 10.0);
  c.clearance = 0.5;
  // A robot (or a car's camera) on the road, looking along the street.
  c.robot_start = Vec3(-10.0, -2.0, 0.0);
  c.robot_heading_deg = 0.0;
  c.robot_pitch_deg = 3.0;
  c.robot_step = 0.4;
  c.robot_max_travel = 20.0;
  c.robot_turn_deg_per_step = 1.0;
  c.robot_arm = 0.3;
  c.robot_bounds_min = Vec3(-30.0, -6.0, 0.0);
  c.robot_bounds_max = Vec3(30.0, 0.5, 0.0);
  s.light.base = Vec3(4000, -6000, 7000);  // the sun
  s.light.pivot = Vec3::Zero();
  s.light.ambient = 0.4;
  s.natural = SynthTrajectory::kForward;
  return s;
}

SceneDef corridor_scene(Rng& rng) {
  SceneDef s;
  const double L = rng.uniform(10.0, 15.0);  // half length, along x
  const double W = rng.uniform(0.9, 1.4);    // half width, along y
  const double Z = rng.uniform(2.4, 3.0);
  Material floor = random_material(rng, rng.uniform(0.2, 0.5), 0.6);  // linoleum or tiles
  floor.color_a = floor.color_a * 0.6 + Vec3::Constant(0.15);
  if (rng.uniform() < 0.6) {
    floor.pattern = Pattern::kTiles;
    floor.period_u = floor.period_v = rng.uniform(0.3, 0.6);
    floor.accent = floor.color_a * 0.6;
  }
  s.prims.push_back(make_rect(Vec3(0, 0, 0), Vec3::UnitZ(), Vec3::UnitX(), L, W, floor));
  Material ceiling;  // weakly textured
  ceiling.color_a = Vec3(0.78, 0.78, 0.76);
  ceiling.color_b = Vec3(0.93, 0.93, 0.9);
  ceiling.strength = 0.05;
  ceiling.scale = 0.5;
  ceiling.seed = rng.bits();
  s.prims.push_back(make_rect(Vec3(0, 0, Z), -Vec3::UnitZ(), Vec3::UnitX(), L, W, ceiling));
  Material panel;  // ceiling lights: bright and textureless
  panel.color_a = Vec3(0.95, 0.95, 0.92);
  panel.color_b = Vec3(1.0, 1.0, 0.97);
  panel.strength = 0.02;
  panel.seed = rng.bits();
  for (double x = -L + rng.uniform(0.8, 1.5); x < L - 0.5; x += rng.uniform(2.0, 3.0)) {
    s.prims.push_back(make_rect(Vec3(x, 0, Z - 0.01), -Vec3::UnitZ(), Vec3::UnitX(), 0.3, 0.5 * W, panel));
  }
  Material skirting = random_material(rng, 0.1, 0.1);
  for (double side : {-1.0, 1.0}) {
    const Vec3 inward = -side * Vec3::UnitY();
    Material wall = random_material(rng, rng.uniform(0.2, 0.8), rng.uniform() < 0.3 ? 0.05 : 0.7);
    wall.color_a = wall.color_a * 0.5 + Vec3::Constant(0.35);
    wall.color_b = wall.color_b * 0.3 + Vec3::Constant(0.6);
    s.prims.push_back(make_rect(Vec3(0, side * W, Z / 2), inward, Vec3::UnitX(), L, Z / 2, wall));
    Material end_wall = random_material(rng, rng.uniform(0.2, 0.6), 0.8);
    s.prims.push_back(make_rect(Vec3(side * L, 0, Z / 2), -side * Vec3::UnitX(), Vec3::UnitY(), W, Z / 2, end_wall));
    s.prims.push_back(make(Shape::kBox, Vec3(0, side * (W - 0.01), 0.05), Vec3(L, 0.01, 0.05), skirting));
    // What lines a corridor, one after another along the wall; nothing sticks out more than
    // 0.45 m, which keeps the middle free for the robot.
    const double wall_y = side * W;
    for (double x = -L + rng.uniform(0.5, 2.0); x < L - 1.5;) {
      double width = 1.0;
      switch (rng.integer(0, 5)) {
        case 0: {  // a door with a handle
          Material door = random_material(rng, rng.uniform(0.05, 0.2), rng.uniform() < 0.4 ? 0.05 : 0.8);
          if (rng.uniform() < 0.5) {
            door.pattern = Pattern::kWood;
            door.period_u = rng.uniform(0.03, 0.08);
          }
          s.prims.push_back(make_rect(Vec3(x + 0.5, wall_y + inward.y() * 0.02, 1.03), inward, Vec3::UnitX(), 0.46, 1.03, door));
          Material handle = random_material(rng, 0.01, 0.1);
          handle.specular = 0.9;
          s.prims.push_back(make(Shape::kSphere, Vec3(x + 0.85, wall_y + inward.y() * 0.07, 1.0), Vec3::Constant(0.03), handle));
          break;
        }
        case 1: {  // a pillar
          width = 0.4;
          s.prims.push_back(make(Shape::kBox, Vec3(x + 0.2, wall_y + inward.y() * 0.15, Z / 2), Vec3(0.2, 0.15, Z / 2),
                                 random_material(rng, rng.uniform(0.2, 0.5), 0.5)));
          break;
        }
        case 2: {  // a ribbed radiator
          Material rad = random_material(rng, 0.1, 0.3);
          rad.pattern = Pattern::kTiles;
          rad.period_u = 0.05;
          rad.period_v = 1.0;
          rad.accent = rad.color_a * 0.5;
          s.prims.push_back(make(Shape::kBox, Vec3(x + 0.5, wall_y + inward.y() * 0.07, 0.45), Vec3(0.5, 0.05, 0.3), rad));
          break;
        }
        case 3: {  // a bench
          width = 1.4;
          Material bench = random_material(rng, rng.uniform(0.05, 0.15));
          s.prims.push_back(make(Shape::kBox, Vec3(x + 0.7, wall_y + inward.y() * 0.22, 0.45), Vec3(0.7, 0.2, 0.03), bench));
          for (double lx : {0.1, 1.3})
            s.prims.push_back(make(Shape::kBox, Vec3(x + lx, wall_y + inward.y() * 0.22, 0.21), Vec3(0.03, 0.18, 0.21), bench));
          break;
        }
        case 4: {  // a notice board full of posters
          width = 1.2;
          Material board = random_material(rng, rng.uniform(0.03, 0.1), 1.3);
          s.prims.push_back(make_rect(Vec3(x + 0.6, wall_y + inward.y() * 0.015, 1.5), inward, Vec3::UnitX(), 0.6, 0.4, board));
          break;
        }
        default: {  // a bin and a fire extinguisher
          width = 0.6;
          s.prims.push_back(make(Shape::kCylinder, Vec3(x + 0.2, wall_y + inward.y() * 0.25, 0.35), Vec3(0.18, 0.18, 0.35),
                                 random_material(rng, 0.05, 0.4)));
          Material red = random_material(rng, 0.05, 0.15);
          red.color_a = Vec3(0.5, 0.04, 0.03);
          red.color_b = Vec3(0.8, 0.1, 0.08);
          red.specular = 0.6;
          s.prims.push_back(make(Shape::kCylinder, Vec3(x + 0.5, wall_y + inward.y() * 0.1, 0.6), Vec3(0.08, 0.08, 0.25), red));
          break;
        }
      }
      x += width + rng.uniform(0.5, 2.5);
    }
  }
  s.background = Background::kBlack;  // never seen: the corridor is closed
  CameraPlan& c = s.cameras;
  c.focal = 0.8;
  c.path_start = Vec3(-L + 1.0, 0.0, 1.5);
  c.path_end = Vec3(L - 2.0, 0.0, 1.5);
  c.path_yaw_offset_deg = 0.0;
  c.path_pitch_deg = -3.0;
  c.path_yaw_wobble_deg = 5.0;
  c.orbit_center = Vec3(0, 0, 1.2);
  c.orbit_radius = 0.6 * W;
  c.orbit_elevation_deg = 0.0;
  c.orbit_elevation_jitter_deg = 3.0;
  c.orbit_span_deg = 120.0;
  c.random_eye_min = Vec3(-L + 1.0, -W + 0.5, 0.3);
  c.random_eye_max = Vec3(L - 1.0, W - 0.5, 1.6);
  c.random_target_min = Vec3(-L, -W, 0.3);
  c.random_target_max = Vec3(L, W, 2.0);
  c.clearance = 0.25;
  c.robot_start = Vec3(-L + 1.0, 0.0, 0.0);
  c.robot_heading_deg = 0.0;
  c.robot_pitch_deg = 0.0;
  c.robot_step = 0.15;
  c.robot_max_travel = 2 * L - 3.0;
  c.robot_turn_deg_per_step = 1.0;
  c.robot_arm = 0.2;
  c.robot_bounds_min = Vec3(-L + 0.6, -W + 0.5, 0.0);
  c.robot_bounds_max = Vec3(L - 0.6, W - 0.5, 0.0);
  s.light.base = Vec3(0.0, 0.0, Z - 0.2);
  s.light.pivot = Vec3(0.0, 0.0, Z - 0.2);
  s.light.ambient = 0.45;
  s.natural = SynthTrajectory::kDrive;
  return s;
}

// ----------------------------------------------------------------------------------------------
// Cameras.

Camera look_at(const Vec3& eye, const Vec3& target, int width, int height, double focal) {
  Mat3 K;
  K << focal * width, 0, (width - 1) / 2.0, 0, focal * width, (height - 1) / 2.0, 0, 0, 1;
  return Camera::look_at(eye, target, K, width, height);
}

bool inside_any(const std::vector<Primitive>& prims, const Vec3& x, double margin) {
  for (const auto& p : prims)
    if (contains(p, x, margin)) return true;
  return false;
}

// A ground robot's camera: driving forward and turning slowly (kDrive) or turning in place (kTurn).
std::vector<Camera> plan_robot_path(const SceneDef& scene, const SynthConfig& cfg, SynthTrajectory traj, Rng& rng) {
  const CameraPlan& c = scene.cameras;
  const int n = cfg.num_views;
  const double height = rng.uniform(c.robot_height_min, c.robot_height_max);
  const double pitch = deg2rad(c.robot_pitch_deg + rng.uniform(-4.0, 4.0));
  double yaw = deg2rad(c.robot_heading_deg + rng.uniform(-10.0, 10.0));
  const double jitter = 0.1 * c.robot_step * n;  // start-position spread, in the path's scale
  auto clear = [&](const Vec3& p) {
    return (p.head<2>().array() >= c.robot_bounds_min.head<2>().array()).all() &&
           (p.head<2>().array() <= c.robot_bounds_max.head<2>().array()).all() && !inside_any(scene.prims, p, c.clearance);
  };
  Vec3 pos(c.robot_start.x() + rng.uniform(-jitter, jitter), c.robot_start.y() + rng.uniform(-jitter, jitter), height);
  if (!clear(pos)) pos = Vec3(c.robot_start.x(), c.robot_start.y(), height);
  std::vector<Camera> cams;
  auto add = [&](const Vec3& eye, double heading) {
    const Vec3 dir(std::cos(pitch) * std::cos(heading), std::cos(pitch) * std::sin(heading), std::sin(pitch));
    cams.push_back(look_at(eye, eye + dir, cfg.width, cfg.height, c.focal));
  };
  if (traj == SynthTrajectory::kTurn) {
    const double span = deg2rad(rng.uniform(60.0, 120.0)) * (rng.uniform() < 0.5 ? -1.0 : 1.0);
    const double arm = c.robot_arm * rng.uniform(0.6, 1.4);
    for (int i = 0; i < n; ++i) {
      const double heading = yaw + (n > 1 ? (static_cast<double>(i) / (n - 1) - 0.5) : 0.0) * span;
      add(pos + arm * Vec3(std::cos(heading), std::sin(heading), 0.0), heading);
    }
    return cams;
  }
  const double step = std::min(c.robot_step * rng.uniform(0.6, 1.4), c.robot_max_travel / std::max(1, n - 1));
  const double turn_rate = deg2rad(c.robot_turn_deg_per_step) * rng.uniform(-1.0, 1.0);
  for (int i = 0; i < n; ++i) {
    add(pos + Vec3(0, 0, 0.01 * c.robot_step * std::sin(2.3 * i)), yaw);  // a little bounce
    const Vec3 next = pos + step * Vec3(std::cos(yaw), std::sin(yaw), 0.0);
    if (clear(next)) {
      pos = next;
      yaw += turn_rate;
    } else {
      yaw += deg2rad(yaw > deg2rad(c.robot_heading_deg) ? -10.0 : 10.0);  // blocked: stop, turn back to the lane
    }
  }
  return cams;
}

std::vector<Camera> plan_cameras(const SceneDef& scene, const SynthConfig& cfg, SynthTrajectory traj, Rng& rng) {
  if (traj == SynthTrajectory::kDrive || traj == SynthTrajectory::kTurn) return plan_robot_path(scene, cfg, traj, rng);
  const CameraPlan& c = scene.cameras;
  const int n = cfg.num_views;
  std::vector<Camera> cams;
  for (int i = 0; i < n; ++i) {
    const double f = n > 1 ? static_cast<double>(i) / (n - 1) : 0.5;
    Vec3 eye, target;
    switch (traj) {
      case SynthTrajectory::kOrbit: {
        const double az = deg2rad(c.orbit_azimuth_deg + (f - 0.5) * c.orbit_span_deg);
        const double el = deg2rad(c.orbit_elevation_deg + (i % 2 ? 1.0 : -1.0) * c.orbit_elevation_jitter_deg);
        eye = c.orbit_center + c.orbit_radius * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
        target = c.orbit_center;
        break;
      }
      case SynthTrajectory::kForward: {
        eye = c.path_start + f * (c.path_end - c.path_start);
        const Vec3 dir = c.path_end - c.path_start;
        const double yaw = std::atan2(dir.y(), dir.x()) + deg2rad(c.path_yaw_offset_deg + c.path_yaw_wobble_deg * std::sin(1.7 * i));
        const double pitch = deg2rad(c.path_pitch_deg);
        target = eye + Vec3(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch));
        break;
      }
      default: {  // kRandom: reject eyes inside objects and (almost) vertical views
        for (int attempt = 0; attempt < 1000; ++attempt) {
          for (int k = 0; k < 3; ++k) eye[k] = rng.uniform(c.random_eye_min[k], c.random_eye_max[k]);
          for (int k = 0; k < 3; ++k) target[k] = rng.uniform(c.random_target_min[k], c.random_target_max[k]);
          const Vec3 d = target - eye;
          if (d.norm() > 1e-3 && std::abs(d.normalized().z()) < 0.9 &&
              !inside_any(scene.prims, eye, c.clearance)) {
            break;
          }
        }
        break;
      }
    }
    cams.push_back(look_at(eye, target, cfg.width, cfg.height, c.focal));
  }
  return cams;
}

// ----------------------------------------------------------------------------------------------
// Rendering.

struct ViewLight {
  Vec3 position;
  double ambient = 0.35, gain = 1.0;
  Vec3 bias = Vec3::Zero();
  bool specular = false;
};

class Tracer {
 public:
  Tracer(const SceneDef& scene, double texture_strength, const PhotoTextureBank& photos)
      : scene_(scene), strength_(texture_strength), photos_(photos) {}

  Hit trace(const Vec3& o, const Vec3& d, double t_min = 1e-9) const {
    Hit hit;
    for (size_t i = 0; i < scene_.prims.size(); ++i) {
      if (intersect(scene_.prims[i], o, d, t_min, &hit)) hit.prim = static_cast<int>(i);
    }
    return hit;
  }

  // `footprint`: a ray's pixel width on the surface (scene units), for the photographs' mip level.
  Vec3 albedo_at(const Hit& h, double footprint = 0.0) const {
    const Material& m = scene_.prims[h.prim].material;
    int ua, va;
    surface_axes(h.normal_local, &ua, &va);
    if (m.photo.texture < 0) return albedo(m, h.local, ua, va, strength_);
    // The material's texture strength scales the photograph's contrast about its mean.
    const double s = std::clamp(m.strength * strength_, 0.0, 2.0);
    const Vec3 mean = photos_.mean_colour(m.photo.texture).cwiseProduct(m.photo.tint);
    const Vec3 photo = mean + (photos_.sample(m.photo, h.local, h.normal_local, footprint) - mean) * s;
    return albedo(m, h.local, ua, va, strength_, &photo);
  }

  // `pixel_angle`: the angle between neighbouring rays (radians).
  Vec3 radiance(const Vec3& o, const Vec3& d, const ViewLight& light, double pixel_angle = 0.0) const {
    const Hit h = trace(o, d);
    if (h.prim < 0) return background(d);
    const Primitive& p = scene_.prims[h.prim];
    const Vec3 x = o + h.t * d;
    Vec3 n = p.R * h.normal_local;
    if (n.dot(d) > 0) n = -n;
    const Vec3 l = (light.position - x).normalized();
    const double diffuse = std::max(0.0, n.dot(l));
    // Oblique surfaces stretch the pixel along one axis: the geometric mean of both stretches.
    const double footprint = h.t * pixel_angle / std::sqrt(std::max(0.05, -n.dot(d)));
    Vec3 col = albedo_at(h, footprint) * (light.ambient + (1.0 - light.ambient) * diffuse);
    if (light.specular && p.material.specular > 0 && diffuse > 0) {
      const Vec3 half = (l - d).normalized();
      col += Vec3::Constant(p.material.specular * std::pow(std::max(0.0, n.dot(half)), 40.0));
    }
    return col;
  }

  Vec3 background(const Vec3& d) const {
    if (scene_.background == Background::kBlack) return Vec3::Constant(0.02);
    const double up = std::clamp(d.z(), 0.0, 1.0);
    return Vec3(0.85, 0.9, 0.95) + (Vec3(0.45, 0.62, 0.9) - Vec3(0.85, 0.9, 0.95)) * std::sqrt(up);
  }

 private:
  const SceneDef& scene_;
  double strength_;
  const PhotoTextureBank& photos_;
};

ViewLight view_light(const SceneDef& scene, const SynthConfig& cfg, int view, Rng& rng) {
  ViewLight l;
  l.position = scene.light.base;
  l.ambient = scene.light.ambient;
  if (!cfg.lighting_change) return l;
  // The light turns about the vertical axis through the pivot by up to +-60 degrees.
  const double angle = deg2rad(rng.uniform(-60.0, 60.0));
  const Vec3 r = l.position - scene.light.pivot;
  l.position = scene.light.pivot + Eigen::AngleAxisd(angle, Vec3::UnitZ()) * r;
  l.gain = rng.uniform(0.75, 1.2);
  const double b = rng.uniform(-0.05, 0.05);
  l.bias = Vec3(b + rng.uniform(-0.01, 0.01), b + rng.uniform(-0.01, 0.01), b + rng.uniform(-0.01, 0.01));
  l.specular = cfg.specular;
  (void)view;
  return l;
}

SynthView render_view(const Tracer& tracer, const Camera& cam, const ViewLight& light, int ss) {
  const int W = cam.width, H = cam.height;
  auto image = torch::empty({H, W, 3}, torch::kUInt8);
  auto depth = torch::zeros({H, W}, torch::kFloat32);
  uint8_t* img = image.data_ptr<uint8_t>();
  float* dep = depth.data_ptr<float>();
  const Mat3 Kinv = cam.K.inverse();
  const Mat3 Rt = cam.R().transpose();
  const Vec3 eye = cam.center();
  const Vec3 axis = cam.viewing_direction();
  const double pixel_angle = 1.0 / (cam.K(0, 0) * ss);
  at::parallel_for(0, H, 1, [&](int64_t y0, int64_t y1) {
    for (int64_t y = y0; y < y1; ++y) {
      for (int x = 0; x < W; ++x) {
        Vec3 sum = Vec3::Zero();
        for (int sy = 0; sy < ss; ++sy) {
          for (int sx = 0; sx < ss; ++sx) {
            const double u = x - 0.5 + (sx + 0.5) / ss, v = y - 0.5 + (sy + 0.5) / ss;
            const Vec3 d = (Rt * (Kinv * Vec3(u, v, 1.0))).normalized();
            sum += tracer.radiance(eye, d, light, pixel_angle);
          }
        }
        Vec3 col = sum / (ss * ss);
        col = (light.gain * col + light.bias).cwiseMax(0.0).cwiseMin(1.0);
        uint8_t* px = img + (y * W + x) * 3;
        for (int k = 0; k < 3; ++k) px[k] = static_cast<uint8_t>(std::lround(col[k] * 255.0));
        const Vec3 d = (Rt * (Kinv * Vec3(x, static_cast<double>(y), 1.0))).normalized();
        const Hit h = tracer.trace(eye, d);
        dep[y * W + x] = h.prim >= 0 ? static_cast<float>(h.t * d.dot(axis)) : 0.0f;
      }
    }
  });
  SynthView view;
  view.camera = cam;
  view.image = image;
  view.depth = depth;
  return view;
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

PointCloud sample_gt_cloud(const SceneDef& scene, const Tracer& tracer, const std::vector<Camera>& cams,
                           int samples, uint64_t seed, double* spacing) {
  std::vector<double> cdf;
  double total = 0.0;
  for (const auto& p : scene.prims) cdf.push_back(total += surface_area(p));
  *spacing = std::sqrt(total / samples);
  std::vector<Eigen::Vector3f> points(samples);
  std::vector<std::array<uint8_t, 3>> colors(samples);
  std::vector<uint8_t> seen(samples, 0);
  at::parallel_for(0, samples, 256, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      const uint64_t base = mix64(seed * 0x2545f4914f6cdd1dULL + static_cast<uint64_t>(i));
      const double pick = to_unit(mix64(base ^ 1)) * total;
      const int k = std::min<int>(static_cast<int>(std::upper_bound(cdf.begin(), cdf.end(), pick) - cdf.begin()),
                                  static_cast<int>(cdf.size()) - 1);
      const Primitive& p = scene.prims[k];
      const double u[3] = {to_unit(mix64(base ^ 2)), to_unit(mix64(base ^ 3)), to_unit(mix64(base ^ 4))};
      Vec3 q = Vec3::Zero(), n = Vec3::UnitZ();
      sample_surface(p, u, &q, &n);
      const Vec3 x = p.R * q + p.center;
      for (const Camera& cam : cams) {
        Eigen::Vector2d uv;
        if (!cam.project(x, &uv) || !cam.in_image(uv)) continue;
        const Vec3 eye = cam.center();
        const double dist = (x - eye).norm();
        const Hit h = tracer.trace(eye, (x - eye) / dist);
        if (h.t >= dist * (1.0 - 1e-7) - 1e-9) {  // nothing in front of the point
          seen[i] = 1;
          break;
        }
      }
      if (!seen[i]) continue;
      Hit local;
      local.prim = k;
      local.local = q;
      local.normal_local = n;
      const Vec3 a = tracer.albedo_at(local);
      points[i] = x.cast<float>();
      for (int c = 0; c < 3; ++c) colors[i][c] = static_cast<uint8_t>(std::lround(a[c] * 255.0));
    }
  });
  PointCloud cloud;
  for (int i = 0; i < samples; ++i) {
    if (!seen[i]) continue;
    cloud.points.push_back(points[i]);
    cloud.colors.push_back(colors[i]);
  }
  return cloud;
}

// Gives a share of the textured surfaces a photograph. Drawn from the material's own seed and the
// scene seed, so primitives sharing a material (a table's top and legs) wear the same photograph
// and the layout's random stream is untouched: without photographs a scene is the same as before.
void assign_photo_textures(SceneDef* scene, const SynthConfig& cfg, const PhotoTextureBank& bank) {
  if (bank.empty()) return;
  for (Primitive& p : scene->prims) {
    Material& m = p.material;
    if (m.strength < 0.2) continue;  // textureless on purpose (plain walls, ceilings): stays so
    Rng rng(m.seed ^ mix64(cfg.seed + 0x70686f746fULL));
    if (rng.uniform() >= cfg.photo_texture_fraction) continue;
    m.photo.texture = rng.integer(0, bank.size() - 1);
    // About 3-10 noise features per 256 texels: small tiling patterns repeat, photographs spread.
    m.photo.size = m.scale * rng.uniform(3.0, 10.0) * std::clamp(bank.width(m.photo.texture) / 256.0, 0.25, 2.0);
    m.photo.angle = deg2rad(90.0 * rng.integer(0, 3) + rng.uniform(-10.0, 10.0));
    m.photo.offset = Eigen::Vector2d(rng.uniform(), rng.uniform());
    const double gain = rng.uniform(0.7, 1.15);
    m.photo.tint = gain * Vec3(rng.uniform(0.85, 1.15), rng.uniform(0.85, 1.15), rng.uniform(0.85, 1.15));
  }
}

void validate(const SynthConfig& c) {
  auto fail = [](const std::string& m) { throw std::invalid_argument("synthetic scene: " + m); };
  if (c.num_views < 1 || c.num_views > 10000) fail("num_views must be in [1, 10000], got " + std::to_string(c.num_views));
  if (c.width < 8 || c.height < 8 || c.width > 16384 || c.height > 16384) {
    fail("image size must be between 8 and 16384 pixels each way, got " + std::to_string(c.width) + "x" + std::to_string(c.height));
  }
  if (c.supersample < 1 || c.supersample > 8) fail("supersample must be in [1, 8], got " + std::to_string(c.supersample));
  if (!(c.texture_strength >= 0.0 && c.texture_strength <= 2.0)) fail("texture_strength must be in [0, 2]");
  if (c.gt_cloud_samples < 0) fail("gt_cloud_samples must not be negative");
  if (!(c.photo_texture_fraction >= 0.0 && c.photo_texture_fraction <= 1.0)) fail("photo_texture_fraction must be in [0, 1]");
}

}  // namespace

SynthScene render_synthetic_scene(const SynthConfig& config) {
  validate(config);
  Rng layout_rng(config.seed);
  SceneDef def;
  switch (config.scene) {
    case SynthSceneType::kDtuLike: def = dtu_like_scene(layout_rng); break;
    case SynthSceneType::kRoom: def = room_scene(layout_rng); break;
    case SynthSceneType::kFacade: def = facade_scene(layout_rng); break;
    case SynthSceneType::kCorridor: def = corridor_scene(layout_rng); break;
  }
  const SynthTrajectory traj = config.trajectory == SynthTrajectory::kDefault ? def.natural : config.trajectory;
  Rng camera_rng(config.seed * 31 + 7), light_rng(config.seed * 131 + 17);
  const std::vector<Camera> cams = plan_cameras(def, config, traj, camera_rng);
  const PhotoTextureBank photos(config.photo_textures);
  assign_photo_textures(&def, config, photos);
  const Tracer tracer(def, config.texture_strength, photos);

  SynthScene scene;
  double dmin = kInf, dmax = 0.0;
  for (int i = 0; i < config.num_views; ++i) {
    const ViewLight light = view_light(def, config, i, light_rng);
    scene.views.push_back(render_view(tracer, cams[i], light, config.supersample));
    const auto& d = scene.views.back().depth;
    const auto valid = d > 0;
    if (valid.any().item<bool>()) {
      dmin = std::min(dmin, d.masked_select(valid).min().item<double>());
      dmax = std::max(dmax, d.max().item<double>());
    }
  }
  if (dmax <= 0.0) throw std::runtime_error("synthetic scene: no view sees any surface (seed " + std::to_string(config.seed) + ")");
  scene.depth_min = 0.95 * dmin;
  scene.depth_max = 1.05 * dmax;

  // Pairs: MVSNet's score over ~1000 surface points each reference sees.
  for (int r = 0; r < config.num_views; ++r) {
    const auto& v = scene.views[r];
    const int stride = std::max(1, static_cast<int>(std::sqrt(config.width * config.height / 1024.0)));
    const auto acc = v.depth.accessor<float, 2>();
    std::vector<Eigen::Vector3d> pts;
    for (int y = stride / 2; y < config.height; y += stride)
      for (int x = stride / 2; x < config.width; x += stride)
        if (acc[y][x] > 0) pts.push_back(v.camera.backproject(x, y, acc[y][x]));
    std::vector<Camera> others;
    std::vector<int> ids;
    for (int s = 0; s < config.num_views; ++s) {
      if (s == r) continue;
      others.push_back(cams[s]);
      ids.push_back(s);
    }
    std::vector<std::pair<int, double>> ranked;
    for (const auto& sv : rank_source_views(pts, v.camera, others)) {
      if (ranked.size() >= 10) break;
      ranked.emplace_back(ids[sv.index], sv.score);
    }
    scene.pairs.push_back(ranked);
  }

  if (config.gt_cloud_samples > 0) {
    scene.gt_cloud = sample_gt_cloud(def, tracer, cams, config.gt_cloud_samples, config.seed, &scene.gt_cloud_spacing);
  }
  return scene;
}

SynthSceneType synth_scene_from_string(const std::string& name) {
  if (name == "dtu_like" || name == "dtu") return SynthSceneType::kDtuLike;
  if (name == "room") return SynthSceneType::kRoom;
  if (name == "facade") return SynthSceneType::kFacade;
  if (name == "corridor") return SynthSceneType::kCorridor;
  throw std::invalid_argument("unknown synthetic scene '" + name + "' (expected dtu_like, room, facade or corridor)");
}

std::string to_string(SynthSceneType scene) {
  switch (scene) {
    case SynthSceneType::kDtuLike: return "dtu_like";
    case SynthSceneType::kRoom: return "room";
    case SynthSceneType::kFacade: return "facade";
    case SynthSceneType::kCorridor: return "corridor";
  }
  return "?";
}

SynthTrajectory synth_trajectory_from_string(const std::string& name) {
  if (name == "default" || name.empty()) return SynthTrajectory::kDefault;
  if (name == "orbit") return SynthTrajectory::kOrbit;
  if (name == "forward") return SynthTrajectory::kForward;
  if (name == "random") return SynthTrajectory::kRandom;
  if (name == "drive") return SynthTrajectory::kDrive;
  if (name == "turn") return SynthTrajectory::kTurn;
  throw std::invalid_argument("unknown trajectory '" + name + "' (expected default, orbit, forward, random, drive or turn)");
}

std::string to_string(SynthTrajectory trajectory) {
  switch (trajectory) {
    case SynthTrajectory::kDefault: return "default";
    case SynthTrajectory::kOrbit: return "orbit";
    case SynthTrajectory::kForward: return "forward";
    case SynthTrajectory::kRandom: return "random";
    case SynthTrajectory::kDrive: return "drive";
    case SynthTrajectory::kTurn: return "turn";
  }
  return "?";
}

}  // namespace umvs
