// Internals of the synthetic scene renderer (core/synth.h), shared by its parts: deterministic
// randomness, materials and primitives (synth_primitives.cpp), scene recipes (synth_recipes.cpp),
// cameras and rendering (synth.cpp). Not installed; include only from those files.
#pragma once

#include <Eigen/Dense>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <vector>

#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/core/synth_textures.h"

namespace umvs {
namespace synth {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kInf = std::numeric_limits<double>::infinity();

inline double deg2rad(double d) { return d * kPi / 180.0; }

// ----------------------------------------------------------------------------------------------
// Deterministic randomness (no std distributions: their output differs between libraries).

inline uint64_t mix64(uint64_t x) {  // splitmix64 finaliser
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
inline double to_unit(uint64_t h) { return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0); }

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

struct Hit {
  double t = kInf;
  int prim = -1;
  Vec3 normal_local = Vec3::UnitZ();
  Vec3 local = Vec3::Zero();
};

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

// ----------------------------------------------------------------------------------------------
// Solid textures and primitives (synth_primitives.cpp).

// In [0,1]: value noise on an integer lattice / summed over octaves (`p` in units of the largest feature).
double lattice_value(int64_t x, int64_t y, int64_t z, uint64_t seed);
double fbm(const Vec3& p, uint64_t seed, int octaves);
// Albedo at surface point `q` (primitive-local coordinates) whose in-surface axes are `ua`, `va`.
// `photo`: the photograph's colour there when the material wears one (instead of the noise).
Vec3 albedo(const Material& m, const Vec3& q, int ua, int va, double strength_scale, const Vec3* photo = nullptr);

Primitive make(Shape shape, const Vec3& center, const Vec3& half, const Material& m, double yaw = 0.0);
// A rectangle with normal `normal` (world), in-plane axis `u_axis`, half sizes (hu, hv).
Primitive make_rect(const Vec3& center, const Vec3& normal, const Vec3& u_axis, double hu, double hv, const Material& m);
// Nearest intersection with t in (t_min, hit->t); updates *hit and returns true when found.
bool intersect(const Primitive& p, const Vec3& o_world, const Vec3& d_world, double t_min, Hit* hit);
bool contains(const Primitive& p, const Vec3& x_world, double margin);
// The two local axes spanning the surface at a hit (for tiles and windows).
void surface_axes(const Vec3& n_local, int* ua, int* va);
double surface_area(const Primitive& p);
// A uniform point on the surface (local coordinates) and its local normal; u[0..2] uniform in [0,1).
void sample_surface(const Primitive& p, const double u[3], Vec3* q, Vec3* n);

// ----------------------------------------------------------------------------------------------
// Scene recipes (synth_recipes.cpp).

Material random_material(Rng& rng, double scale, double strength = 1.0);
SceneDef dtu_like_scene(Rng& rng);
SceneDef room_scene(Rng& rng);
SceneDef facade_scene(Rng& rng);
SceneDef corridor_scene(Rng& rng);

}  // namespace synth
}  // namespace umvs
