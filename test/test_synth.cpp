#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>

#include "unsup_mvs/core/synth.h"

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

// Every reference pixel is moved into view 1 with its ground-truth depth. Where it lands inside a
// 2x2 block of view-1 pixels that lie on one plane (inverse depth is then bilinear in the pixel
// coordinates, so interpolation is exact), view 1's depth there must equal the moved point's depth.
struct Reprojection {
  std::vector<double> rel_depth_error;
  std::vector<double> colour_error;
};

Reprojection reproject(const SynthScene& s) {
  const auto& a = s.views[0];
  const auto& b = s.views[1];
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

}  // namespace
}  // namespace umvs
