// Scene recipes of `umvs synth` that a camera walks through: a street between facades and an
// office corridor (docs/synthetic.md); the others are in synth_recipes.cpp.
#include <cmath>

#include "synth_scene.h"

namespace umvs {
namespace synth {

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

}  // namespace synth
}  // namespace umvs
