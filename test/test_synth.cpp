#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "test_util.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/core/synth_textures.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/synth_writer.h"

namespace umvs {
namespace {

SynthConfig small_room(bool lighting_change) {
  SynthConfig c;
  c.scene = SynthSceneType::kRoom;
  c.seed = 3;
  c.num_views = 4;
  c.width = 160;
  c.height = 128;
  c.lighting_change = lighting_change;
  c.gt_cloud_samples = 0;
  return c;
}

TEST(Synth, SameSeedGivesIdenticalScenes) {
  const SynthScene a = render_synthetic_scene(small_room(true));
  const SynthScene b = render_synthetic_scene(small_room(true));
  ASSERT_EQ(a.views.size(), 4u);
  for (size_t v = 0; v < a.views.size(); ++v) {
    EXPECT_TRUE(torch::equal(a.views[v].image, b.views[v].image));
    EXPECT_TRUE(torch::equal(a.views[v].depth, b.views[v].depth));
    EXPECT_TRUE(a.views[v].camera.T_cam_world == b.views[v].camera.T_cam_world);
  }
  SynthConfig other = small_room(true);
  other.seed = 4;
  EXPECT_FALSE(torch::equal(render_synthetic_scene(other).views[0].image, a.views[0].image));
  EXPECT_GT(a.depth_min, 0.0);
  EXPECT_GT(a.depth_max, a.depth_min);
}

// A path seed is another pass through the same scene: new camera poses, but the same surfaces, so
// each new view's ground-truth depth agrees with the first pass's wherever both see a point.
TEST(Synth, PathSeedGivesAnotherPathThroughTheSameScene) {
  const SynthConfig first = small_room(true);
  SynthConfig second = first;
  second.path_seed = 77;
  const SynthScene a = render_synthetic_scene(first);
  const SynthScene b = render_synthetic_scene(second);
  EXPECT_TRUE(torch::equal(render_synthetic_scene(second).views[0].image, b.views[0].image));
  ASSERT_EQ(b.views.size(), a.views.size());
  const Camera& ca = a.views[0].camera;
  const Camera& cb = b.views[0].camera;
  const double moved = (ca.center() - cb.center()).norm();
  EXPECT_GT(moved, 0.01) << "the second pass starts where the first did";
  // Points of the second pass's first view, moved into the first pass's first view: where they
  // land in front of the first view's surface, the depths agree (same geometry).
  auto db = b.views[0].depth.accessor<float, 2>();
  auto da = a.views[0].depth.accessor<float, 2>();
  int compared = 0, agreed = 0;
  for (int y = 0; y < cb.height; y += 4) {
    for (int x = 0; x < cb.width; x += 4) {
      const double d = db[y][x];
      if (d <= 0) continue;
      Eigen::Vector2d uv;
      double z = 0.0;
      if (!ca.project(cb.backproject(x, y, d), &uv, &z)) continue;
      const long u = std::lround(uv.x()), v = std::lround(uv.y());
      if (u < 0 || v < 0 || u >= ca.width || v >= ca.height || da[v][u] <= 0) continue;
      ++compared;
      agreed += std::abs(da[v][u] - z) < 0.02 * z;
    }
  }
  ASSERT_GT(compared, 200) << "the two passes see too little of the same scene";
  EXPECT_GT(static_cast<double>(agreed) / compared, 0.7) << agreed << " of " << compared;
}

// Every pixel of view `ref` is moved into view `src` with its ground-truth depth. Where it lands
// inside a 2x2 block of `src` pixels that lie on one plane (inverse depth is then bilinear in the pixel
// coordinates, so interpolation is exact), `src`'s depth there must equal the moved point's depth.
struct Reprojection {
  std::vector<double> rel_depth_error;
  std::vector<double> colour_error;
};

Reprojection reproject(const SynthScene& s, int ref = 0, int src = 1) {
  const auto& a = s.views[ref];
  const auto& b = s.views[src];
  auto da = a.depth.accessor<float, 2>();
  auto db = b.depth.accessor<float, 2>();
  auto ia = a.image.accessor<uint8_t, 3>();
  auto ib = b.image.accessor<uint8_t, 3>();
  Reprojection out;
  for (int y = 0; y < a.camera.height; ++y) {
    for (int x = 0; x < a.camera.width; ++x) {
      if (da[y][x] <= 0) continue;
      const Eigen::Vector3d X = a.camera.backproject(x, y, da[y][x]);
      Eigen::Vector2d uv;
      double z;
      if (!b.camera.project(X, &uv, &z)) continue;
      const int u0 = static_cast<int>(std::floor(uv.x())), v0 = static_cast<int>(std::floor(uv.y()));
      if (u0 < 0 || v0 < 0 || u0 + 1 >= b.camera.width || v0 + 1 >= b.camera.height) continue;
      const double i00 = 1 / db[v0][u0], i01 = 1 / db[v0][u0 + 1], i10 = 1 / db[v0 + 1][u0], i11 = 1 / db[v0 + 1][u0 + 1];
      if (!(db[v0][u0] > 0 && db[v0][u0 + 1] > 0 && db[v0 + 1][u0] > 0 && db[v0 + 1][u0 + 1] > 0)) continue;
      if (std::abs(i00 + i11 - i01 - i10) > 1e-6 * i00) continue;  // not one plane (edge, occlusion, curve)
      const double fu = uv.x() - u0, fv = uv.y() - v0;
      const double inv = (1 - fv) * ((1 - fu) * i00 + fu * i01) + fv * ((1 - fu) * i10 + fu * i11);
      const double rel = std::abs(1 / inv - z) / z;
      if (rel > 0.05) continue;  // another surface in front: occluded in view 1
      out.rel_depth_error.push_back(rel);
      double c = 0;
      for (int k = 0; k < 3; ++k) {
        const double vb = (1 - fv) * ((1 - fu) * ib[v0][u0][k] + fu * ib[v0][u0 + 1][k]) +
                          fv * ((1 - fu) * ib[v0 + 1][u0][k] + fu * ib[v0 + 1][u0 + 1][k]);
        c += std::abs(vb - ia[y][x][k]) / 255.0 / 3;
      }
      out.colour_error.push_back(c);
    }
  }
  return out;
}

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * (v.size() - 1))];
}

TEST(Synth, GroundTruthDepthIsConsistentAcrossViews) {
  const Reprojection r = reproject(render_synthetic_scene(small_room(false)));
  ASSERT_GT(r.rel_depth_error.size(), 2000u);
  std::cout << "[synth] " << r.rel_depth_error.size() << " reprojected pixels, rel depth error median "
            << quantile(r.rel_depth_error, 0.5) << ", p99 " << quantile(r.rel_depth_error, 0.99) << "\n";
  EXPECT_LT(quantile(r.rel_depth_error, 0.99), 1e-4);
}

TEST(Synth, WithoutLightingChangeViewsAgreePhotometrically) {
  const Reprojection same = reproject(render_synthetic_scene(small_room(false)));
  const Reprojection lit = reproject(render_synthetic_scene(small_room(true)));
  const double med_same = quantile(same.colour_error, 0.5), med_lit = quantile(lit.colour_error, 0.5);
  std::cout << "[synth] colour error after reprojection: median " << med_same << " (fixed light), " << med_lit
            << " (lighting change)\n";
  // Only anti-aliasing and resampling differ: a few grey levels.
  EXPECT_LT(med_same, 0.02);
  EXPECT_LT(med_same, 0.5 * med_lit);
}

// ------------------------------------------------------------------------------------------------
// Photographic textures (core/synth_textures.h).

// A 4x3 image whose texels all differ: texel(x, y) = (10x + 1, 10y + 1, 200).
torch::Tensor numbered_image() {
  auto img = torch::empty({3, 4, 3}, torch::kUInt8);
  auto a = img.accessor<uint8_t, 3>();
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) {
      a[y][x][0] = static_cast<uint8_t>(10 * x + 1);
      a[y][x][1] = static_cast<uint8_t>(10 * y + 1);
      a[y][x][2] = 200;
    }
  return img;
}

TEST(PhotoTextures, LookupHitsTexelCentresAndRepeatsMirrored) {
  const PhotoTextureBank bank({numbered_image()});
  ASSERT_EQ(bank.size(), 1);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) {
      const Eigen::Vector3d c = bank.texel(0, 0, x, y);
      EXPECT_NEAR(c[0] * 255, 10 * x + 1, 1e-4);
      EXPECT_NEAR(c[1] * 255, 10 * y + 1, 1e-4);
    }
  // Halfway between texels: the mean of both; beyond the edge: mirrored (no seam).
  EXPECT_NEAR(bank.texel(0, 0, 1.5, 0)[0] * 255, 16.0, 1e-4);
  EXPECT_NEAR(bank.texel(0, 0, -1, 0)[0] * 255, 1.0, 1e-4);    // texel 0 again
  EXPECT_NEAR(bank.texel(0, 0, 4, 2)[0] * 255, 31.0, 1e-4);    // texel 3 again
  EXPECT_NEAR(bank.texel(0, 0, 0, 3)[1] * 255, 21.0, 1e-4);    // row 2 again
  EXPECT_NEAR(bank.texel(0, 0, 8, 0)[0] * 255, 1.0, 1e-4);     // period 2 x width
  EXPECT_NEAR(bank.mean_colour(0)[0] * 255, 16.0, 1e-4);

  // A surface point maps to texels through size (scene units per image width), offset and tint:
  // on a face with local normal z, (q.x, q.y) / size * width are texel coordinates (+ 0.5).
  PhotoMapping m;
  m.texture = 0;
  m.size = 2.0;  // 0.5 scene units per texel
  m.tint = Eigen::Vector3d(1.0, 1.0, 0.5);
  const Eigen::Vector3d n(0, 0, 1);
  const Eigen::Vector3d c = bank.sample(m, Eigen::Vector3d(2 * 0.5 + 0.25, 1 * 0.5 + 0.25, 7.0), n, 0.0);
  EXPECT_NEAR(c[0] * 255, 21.0, 1e-4);  // texel (2, 1)
  EXPECT_NEAR(c[1] * 255, 11.0, 1e-4);
  EXPECT_NEAR(c[2] * 255, 100.0, 1e-4);
  // A pixel as wide as the whole image reads the coarsest level (4x3 -> 2x1 -> 1x1): the mean.
  ASSERT_EQ(bank.levels(0), 3);
  const Eigen::Vector3d far = bank.sample(m, Eigen::Vector3d(0.1, 0.2, 0.0), n, 4.0);
  EXPECT_NEAR(far[0] * 255, 16.0, 1e-4);
  const Eigen::Vector3d mid = bank.sample(m, Eigen::Vector3d(0.1, 0.2, 0.0), n, 1.0);  // level 1: 2x1
  EXPECT_NEAR(mid[0] * 255, 6.0, 1e-4);  // left half: texels 1 and 11
  EXPECT_THROW(PhotoTextureBank({torch::zeros({3, 4}, torch::kUInt8)}), std::invalid_argument);
  EXPECT_THROW(PhotoTextureBank({torch::zeros({3, 4, 3}, torch::kFloat32)}), std::invalid_argument);
}

// Pure red and blue squares: a green channel of exactly 0, which no procedural material has.
torch::Tensor red_blue_checker() {
  auto img = torch::zeros({32, 32, 3}, torch::kUInt8);
  auto a = img.accessor<uint8_t, 3>();
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) a[y][x][((x / 8 + y / 8) % 2) ? 0 : 2] = 255;
  return img;
}

// A high-frequency "photograph": noise at several scales (deterministic).
torch::Tensor noisy_photo() {
  torch::manual_seed(11);
  auto fine = torch::rand({3, 128, 128});
  auto coarse = torch::nn::functional::interpolate(
      torch::rand({1, 3, 8, 8}), torch::nn::functional::InterpolateFuncOptions().size(std::vector<int64_t>{128, 128})
                                      .mode(torch::kBilinear).align_corners(false))[0];
  return (0.5 * fine + 0.5 * coarse).mul(255).round().clamp(0, 255).to(torch::kUInt8).permute({1, 2, 0}).contiguous();
}

double share_without_green(const SynthScene& s) {
  int64_t zero = 0, all = 0;
  for (const auto& v : s.views) {
    zero += (v.image.select(2, 1) == 0).sum().item<int64_t>();
    all += v.image.size(0) * v.image.size(1);
  }
  return static_cast<double>(zero) / all;
}

TEST(PhotoTextures, SurfacesWearThePhotographsAndDepthStaysExact) {
  SynthConfig procedural = small_room(false);
  SynthConfig photo = procedural;
  photo.photo_textures = {red_blue_checker()};
  const SynthScene a = render_synthetic_scene(procedural);
  const SynthScene b = render_synthetic_scene(photo);
  const double share_a = share_without_green(a), share_b = share_without_green(b);
  std::cout << "[synth] pixels with green = 0: " << 100 * share_a << "% procedural, " << 100 * share_b
            << "% with a red/blue photograph\n";
  EXPECT_EQ(share_a, 0.0);
  EXPECT_GT(share_b, 0.25);
  for (size_t v = 0; v < a.views.size(); ++v) {
    EXPECT_TRUE(torch::equal(a.views[v].depth, b.views[v].depth)) << "textures must not move geometry";
  }
  // No photograph on any surface: the procedural scene, bit for bit.
  photo.photo_texture_fraction = 0.0;
  const SynthScene c = render_synthetic_scene(photo);
  for (size_t v = 0; v < a.views.size(); ++v) EXPECT_TRUE(torch::equal(a.views[v].image, c.views[v].image));
  photo.photo_texture_fraction = 1.5;
  EXPECT_THROW(render_synthetic_scene(photo), std::invalid_argument);
}

TEST(PhotoTextures, SameSeedAndImagesGiveIdenticalScenes) {
  SynthConfig c = small_room(true);
  c.photo_textures = {noisy_photo(), red_blue_checker()};
  const SynthScene a = render_synthetic_scene(c);
  const SynthScene b = render_synthetic_scene(c);
  for (size_t v = 0; v < a.views.size(); ++v) {
    EXPECT_TRUE(torch::equal(a.views[v].image, b.views[v].image));
    EXPECT_TRUE(torch::equal(a.views[v].depth, b.views[v].depth));
  }
  c.photo_textures = {red_blue_checker(), noisy_photo()};  // other images on the same surfaces
  EXPECT_FALSE(torch::equal(render_synthetic_scene(c).views[0].image, a.views[0].image));
}

TEST(PhotoTextures, ViewsStillAgreePhotometrically) {
  SynthConfig c = small_room(false);
  c.photo_textures = {noisy_photo(), red_blue_checker()};
  c.photo_texture_fraction = 1.0;
  const Reprojection r = reproject(render_synthetic_scene(c));
  ASSERT_GT(r.colour_error.size(), 2000u);
  const double med = quantile(r.colour_error, 0.5);
  std::cout << "[synth] photo textures, fixed light: colour error after reprojection median " << med << ", p90 "
            << quantile(r.colour_error, 0.9) << "\n";
  EXPECT_LT(med, 0.02);
}

// ------------------------------------------------------------------------------------------------
// Scene recipes and robot camera paths: the ground truth the supervised training relies on.

SynthConfig robot_config(SynthSceneType scene, SynthTrajectory traj, int views, uint64_t seed) {
  SynthConfig c;
  c.scene = scene;
  c.trajectory = traj;
  c.seed = seed;
  c.num_views = views;
  c.width = 96;
  c.height = 80;
  c.supersample = 1;
  c.lighting_change = false;
  c.gt_cloud_samples = 0;
  return c;
}

TEST(Synth, CorridorIsClosedAndSeenFromARobot) {
  SynthConfig c = robot_config(SynthSceneType::kCorridor, SynthTrajectory::kDefault, 8, 5);
  c.width = 160;
  c.height = 128;
  c.photo_textures = {noisy_photo()};
  const SynthScene s = render_synthetic_scene(c);
  ASSERT_EQ(s.views.size(), 8u);
  std::cout << "[synth] corridor depth range " << s.depth_min << " .. " << s.depth_max << " m\n";
  EXPECT_GT(s.depth_min, 0.25);  // the eye keeps its clearance from every solid
  EXPECT_LT(s.depth_max, 32.0);  // at most 30 m long
  EXPECT_GT(s.depth_max, 8.0);   // looking down the corridor
  for (size_t v = 0; v < s.views.size(); ++v) {
    EXPECT_TRUE((s.views[v].depth > 0).all().item<bool>()) << "view " << v << ": the corridor is closed";
    const Eigen::Vector3d eye = s.views[v].camera.center();
    EXPECT_GE(eye.z(), 0.29);
    EXPECT_LE(eye.z(), 1.51);
    EXPECT_GT(s.views[v].camera.viewing_direction().x(), 0.9) << "driving along +x";
    if (v > 0) {
      const double step = (eye - s.views[v - 1].camera.center()).norm();
      EXPECT_LT(step, 0.3) << "small baselines";
    }
  }
  for (int v = 0; v + 1 < 8; v += 2) {
    const Reprojection r = reproject(s, v, v + 1);
    ASSERT_GT(r.rel_depth_error.size(), 2000u);
    // p95, not p99: a 2x2 block split along a row or column between parallel surfaces a few
    // centimetres apart (doors, boards, skirting in front of a wall) passes the one-plane check.
    EXPECT_LT(quantile(r.rel_depth_error, 0.95), 1e-4);
    EXPECT_LT(quantile(r.rel_depth_error, 0.5), 1e-6);
  }
}

TEST(Synth, RobotPathsGiveConsistentDepthInEveryRecipe) {
  for (SynthSceneType scene : {SynthSceneType::kDtuLike, SynthSceneType::kRoom, SynthSceneType::kFacade, SynthSceneType::kCorridor}) {
    for (SynthTrajectory traj : {SynthTrajectory::kDrive, SynthTrajectory::kTurn}) {
      const SynthScene s = render_synthetic_scene(robot_config(scene, traj, 4, 21));
      const std::string what = to_string(scene) + "/" + to_string(traj);
      const Reprojection r = reproject(s, 1, 2);
      ASSERT_GT(r.rel_depth_error.size(), 500u) << what;
      EXPECT_LT(quantile(r.rel_depth_error, 0.95), 1e-4) << what;  // p95: see the corridor test
      EXPECT_LT(quantile(r.rel_depth_error, 0.5), 1e-6) << what;
      double baseline = 0.0;
      for (int v = 1; v < 4; ++v) baseline = std::max(baseline, (s.views[v].camera.center() - s.views[v - 1].camera.center()).norm());
      EXPECT_GT(baseline, 0.0) << what << ": the camera moves";
      if (scene != SynthSceneType::kDtuLike) {  // metric scenes: a ground robot's camera height
        for (const auto& v : s.views) {
          EXPECT_GE(v.camera.center().z(), 0.29) << what;
          EXPECT_LE(v.camera.center().z(), 1.51) << what;
        }
      }
      std::cout << "[synth] " << what << ": depth " << s.depth_min << " .. " << s.depth_max << ", largest step "
                << baseline << ", " << r.rel_depth_error.size() << " pixels reprojected\n";
    }
  }
  EXPECT_EQ(synth_scene_from_string("corridor"), SynthSceneType::kCorridor);
  EXPECT_EQ(synth_trajectory_from_string("drive"), SynthTrajectory::kDrive);
  EXPECT_EQ(synth_trajectory_from_string("turn"), SynthTrajectory::kTurn);
}

// What training reads: the written cams and depth_gt, not the in-memory scene.
TEST(Synth, WrittenCamsAndDepthReprojectConsistently) {
  SynthConfig c = robot_config(SynthSceneType::kRoom, SynthTrajectory::kDrive, 3, 8);
  c.photo_textures = {noisy_photo()};
  const SynthScene s = render_synthetic_scene(c);
  const std::string dir = test::temp_dir("synth_written");
  write_synthetic_scene(dir, s, c, {"/some/folder"});
  SynthScene back;
  for (int v = 0; v < 3; ++v) {
    const std::string stem = view_file_stem(v);
    SynthView view;
    view.camera = read_cam_file(dir + "/cams/" + stem + "_cam.txt").camera;
    view.camera.width = c.width;
    view.camera.height = c.height;
    view.depth = read_pfm(dir + "/depth_gt/" + stem + ".pfm");
    view.image = read_image_rgb8(dir + "/images/" + stem + ".png");
    EXPECT_TRUE(torch::equal(view.depth, s.views[v].depth));
    EXPECT_TRUE(torch::equal(view.image, s.views[v].image));
    back.views.push_back(view);
  }
  for (int v = 0; v < 2; ++v) {
    const Reprojection r = reproject(back, v, v + 1);
    ASSERT_GT(r.rel_depth_error.size(), 1000u);
    EXPECT_LT(quantile(r.rel_depth_error, 0.99), 1e-4);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace umvs
