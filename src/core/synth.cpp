#include "unsup_mvs/core/synth.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "unsup_mvs/core/synth_textures.h"
#include "unsup_mvs/core/view_selection.h"

#include "synth_scene.h"

namespace umvs {
namespace {

using namespace synth;

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

// Another pass along a recipe's fixed path (orbit and forward paths draw nothing from the seed):
// the views fall between the first pass's, inside the recipe's span, a little to the side and
// higher or lower, so that they see the same surfaces from new viewpoints. Drive, turn and random
// paths differ by the seed alone.
CameraPlan another_pass(const SceneDef& scene, int num_views, Rng& rng) {
  CameraPlan c = scene.cameras;
  // Trim the span's start by `head` and its end by `tail` (fractions of it, half a view spacing
  // in all), so that the views sit between the recipe's views and never beyond its ends.
  const double spacing = 1.0 / std::max(1, num_views - 1);
  const double head = rng.uniform(0.1, 0.4) * spacing, tail = 0.5 * spacing - head;
  c.orbit_azimuth_deg += 0.5 * (head - tail) * c.orbit_span_deg;
  c.orbit_span_deg *= 1.0 - head - tail;
  c.orbit_radius *= rng.uniform(0.9, 1.1);
  c.orbit_elevation_deg += rng.uniform(-4.0, 4.0);
  const Vec3 along = c.path_end - c.path_start;
  c.path_start += head * along;
  c.path_end -= tail * along;
  const Vec3 side = Vec3(-along.y(), along.x(), 0.0).normalized();
  auto eyes_in_solids = [&](const Vec3& shift) {
    int n = 0;
    for (int i = 0; i < num_views; ++i) {
      const double f = num_views > 1 ? static_cast<double>(i) / (num_views - 1) : 0.5;
      n += inside_any(scene.prims, c.path_start + shift + f * (c.path_end - c.path_start), c.clearance);
    }
    return n;
  };
  // Sideways and up or down only where that puts no more eyes into furniture than the trimmed path.
  const int trimmed = eyes_in_solids(Vec3::Zero());
  for (int attempt = 0; attempt < 20; ++attempt) {
    const Vec3 shift = rng.uniform(-0.05, 0.05) * along.norm() * side + Vec3(0, 0, rng.uniform(-0.02, 0.02) * along.norm());
    if (eyes_in_solids(shift) <= trimmed) {
      c.path_start += shift;
      c.path_end += shift;
      break;
    }
  }
  return c;
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
  Rng camera_rng(config.path_seed.value_or(config.seed) * 31 + 7), light_rng(config.seed * 131 + 17);
  if (config.path_seed && (traj == SynthTrajectory::kOrbit || traj == SynthTrajectory::kForward)) {
    def.cameras = another_pass(def, config.num_views, camera_rng);
  }
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
