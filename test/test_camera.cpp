#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/view_selection.h"

namespace umvs {
namespace {

Camera make_camera() {
  Camera c;
  c.width = 640;
  c.height = 480;
  c.K << 500, 0, 319.5, 0, 505, 239.5, 0, 0, 1;
  Eigen::Matrix3d R = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitX())).toRotationMatrix();
  c.T_cam_world.topLeftCorner<3, 3>() = R;
  c.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(0.1, -0.2, 1.5);
  return c;
}

TEST(Camera, ProjectBackprojectRoundTrip) {
  const Camera c = make_camera();
  for (double u : {0.0, 100.5, 639.0}) {
    for (double d : {0.5, 3.0}) {
      const Eigen::Vector3d X = c.backproject(u, 200.0, d);
      Eigen::Vector2d uv;
      double depth;
      ASSERT_TRUE(c.project(X, &uv, &depth));
      EXPECT_NEAR(uv.x(), u, 1e-9);
      EXPECT_NEAR(uv.y(), 200.0, 1e-9);
      EXPECT_NEAR(depth, d, 1e-12);
    }
  }
  EXPECT_FALSE(c.project(c.center() - c.viewing_direction(), nullptr));
}

TEST(Camera, TurnedKeepsTheCentreAndTurnsTheView) {
  // Turning by 1 degree about the camera's own y axis keeps its centre, and moves the image of a
  // far point on the optical axis by fx * tan(1 degree) pixels along x.
  const Camera c = make_camera();
  const double angle = M_PI / 180.0;
  const Camera turned = c.turned(Eigen::Vector3d(0, angle, 0));
  EXPECT_LT((turned.center() - c.center()).norm(), 1e-12);
  EXPECT_NEAR(rotation_angle(turned.R(), c.R()), angle, 1e-12);
  const Eigen::Vector3d far_point = c.backproject(319.5, 239.5, 1e6);
  Eigen::Vector2d before, after;
  ASSERT_TRUE(c.project(far_point, &before));
  ASSERT_TRUE(turned.project(far_point, &after));
  EXPECT_NEAR(after.x() - before.x(), 500.0 * std::tan(angle), 1e-3);
  EXPECT_NEAR(after.y(), before.y(), 1e-6);
  const Camera same = c.turned(Eigen::Vector3d::Zero());
  EXPECT_EQ(same.T_cam_world, c.T_cam_world);
}

TEST(Camera, ResizeMapsPixelCentres) {
  const Camera c = make_camera();
  const Camera half = c.resized(320, 240);
  const Eigen::Vector3d X = c.backproject(101.0, 51.0, 2.0);
  Eigen::Vector2d uv_full, uv_half;
  c.project(X, &uv_full);
  half.project(X, &uv_half);
  // Full-res pixel centre u maps to (u + 0.5) / 2 - 0.5 at half resolution.
  EXPECT_NEAR(uv_half.x(), (uv_full.x() + 0.5) / 2 - 0.5, 1e-9);
  EXPECT_NEAR(uv_half.y(), (uv_full.y() + 0.5) / 2 - 0.5, 1e-9);
  const Camera crop = c.cropped(10, 20, 600, 400);
  Eigen::Vector2d uv_crop;
  crop.project(X, &uv_crop);
  EXPECT_NEAR(uv_crop.x(), uv_full.x() - 10, 1e-9);
  EXPECT_NEAR(uv_crop.y(), uv_full.y() - 20, 1e-9);
}

TEST(Camera, NetworkResizeGivesMultiplesOf32) {
  const NetworkResize plan = plan_network_resize(640, 480, 0, 0);
  EXPECT_EQ(plan.width, 640);
  EXPECT_EQ(plan.height, 480);
  const NetworkResize small = plan_network_resize(1000, 750, 640, 512);
  EXPECT_EQ(small.scaled_width, 640);
  EXPECT_EQ(small.scaled_height, 480);
  EXPECT_EQ(small.width % 32, 0);
  EXPECT_EQ(small.height, 480);
  const NetworkResize odd = plan_network_resize(650, 490, 0, 0);
  EXPECT_EQ(odd.width, 640);
  EXPECT_EQ(odd.height, 480);
  EXPECT_EQ(odd.crop_x, 5);
  EXPECT_EQ(odd.crop_y, 5);
  EXPECT_THROW(plan_network_resize(20, 20, 0, 0), std::invalid_argument);
}

TEST(Camera, ValidateNamesTheProblem) {
  Camera c = make_camera();
  EXPECT_NO_THROW(c.validate());
  c.T_cam_world(0, 3) = std::nan("");
  EXPECT_THAT([&] { c.validate("view 7"); },
              testing::ThrowsMessage<std::invalid_argument>(testing::AllOf(testing::HasSubstr("view 7"), testing::HasSubstr("NaN"))));
  c = make_camera();
  c.T_cam_world(0, 0) *= 2;  // not a rotation
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = make_camera();
  c.K(0, 0) = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

TEST(ViewSelection, ScorePeaksAtTheta0) {
  EXPECT_DOUBLE_EQ(view_angle_score(5.0), 1.0);
  EXPECT_NEAR(view_angle_score(4.0), std::exp(-0.5), 1e-12);   // sigma1 = 1 below theta0
  EXPECT_NEAR(view_angle_score(15.0), std::exp(-0.5), 1e-12);  // sigma2 = 10 above
  EXPECT_LT(view_angle_score(0.5), view_angle_score(10.0));
}

TEST(ViewSelection, RanksTheBestBaselineFirst) {
  Camera ref = make_camera();
  ref.T_cam_world = Eigen::Matrix4d::Identity();
  const auto pts = sample_frustum_points(ref, 2.0, 8);
  std::vector<Camera> cands;
  for (double angle_deg : {1.0, 5.0, 30.0}) {
    // Orbit around the point at depth 2 on the optical axis.
    Camera c = ref;
    const double a = angle_deg * M_PI / 180.0;
    Eigen::Matrix3d R = Eigen::AngleAxisd(-a, Eigen::Vector3d::UnitY()).toRotationMatrix();
    const Eigen::Vector3d centre(2.0 * std::sin(a), 0, 2.0 - 2.0 * std::cos(a));
    c.T_cam_world.topLeftCorner<3, 3>() = R;
    c.T_cam_world.topRightCorner<3, 1>() = -R * centre;
    cands.push_back(c);
  }
  const auto ranked = rank_source_views(pts, ref, cands);
  ASSERT_GE(ranked.size(), 2u);
  EXPECT_EQ(ranked[0].index, 1);  // 5 degrees
  EXPECT_EQ(ranked[1].index, 2);  // 30 deg: exp(-25^2/200) = 0.04 per point beats 1 deg: exp(-8)
}

// A street drive: the camera looks sideways at facades about 10 m away, the depth range it is
// given is 2.7-45 m (as for the rendered street, whose planes reach far past the facades).
TEST(ViewSelection, AWideDepthRangeIsScoredWhereMostOfTheSceneIs) {
  Camera ref = make_camera();
  ref.T_cam_world = Eigen::Matrix4d::Identity();
  std::vector<Camera> cands;
  for (double baseline : {0.25, 1.0, 4.0}) {
    Camera c = ref;
    c.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(-baseline, 0, 0);  // centre at x = +baseline
    cands.push_back(c);
  }
  const double near = 2.7, far = 45.0;
  const auto best_at = [&](double depth) {
    return rank_source_views(sample_frustum_points(ref, depth), ref, cands).at(0).index;
  };
  const int on_the_facades = best_at(10.0);
  EXPECT_EQ(on_the_facades, 1);  // 1 m: 5.7 degrees at 10 m
  EXPECT_EQ(best_at(view_selection_depth(near, far)), on_the_facades);
  EXPECT_EQ(best_at(0.5 * (near + far)), 2);  // the old rule: 24 m, where only 4 m triangulates

  EXPECT_DOUBLE_EQ(view_selection_depth(2.0, 2.0), 2.0);
  EXPECT_THROW(view_selection_depth(0.0, 10.0), std::invalid_argument);
  EXPECT_THROW(view_selection_depth(5.0, 1.0), std::invalid_argument);
  EXPECT_THROW(view_selection_depth(1.0, std::numeric_limits<double>::infinity()), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
