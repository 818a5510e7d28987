// Scene recipes of `umvs synth`: objects on a table and a furnished room, with their cameras' and
// light's plan (docs/synthetic.md); the street and the corridor are in synth_recipes_walks.cpp.
#include <cmath>

#include "synth_scene.h"

namespace umvs {
namespace synth {

Material random_material(Rng& rng, double scale, double strength) {
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

}  // namespace synth
}  // namespace umvs
