// Parallax of a depth map's pixels in the source views: the geometry behind "unknown" depth.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include "unsup_mvs/core/depth_estimator.h"

namespace umvs {
namespace {

Camera camera_from(const Eigen::Vector3d& center, const Eigen::Matrix3d& R_world_to_cam = Eigen::Matrix3d::Identity()) {
  Camera c;
  c.K << 100, 0, 31.5, 0, 100, 23.5, 0, 0, 1;
  c.width = 64;
  c.height = 48;
  c.T_cam_world.topLeftCorner<3, 3>() = R_world_to_cam;
  c.T_cam_world.topRightCorner<3, 1>() = -R_world_to_cam * center;
  return c;
}

TEST(Parallax, ShiftMatchesTheStereoFormulaAndVanishesForARotation) {
  const Camera ref = camera_from(Eigen::Vector3d::Zero());
  const auto depth = torch::full({48, 64}, 2.0f);
  // A source 10 cm to the side: a depth d -> 1.1 d moves the centre pixel by f b (1/d - 1/1.1d).
  const Camera side = camera_from(Eigen::Vector3d(0.1, 0, 0));
  const auto shift = parallax_shift_px(depth, ref, {side}, 0.1);
  EXPECT_NEAR(shift[23][31].item<float>(), 100 * 0.1 * (1 / 2.0 - 1 / 2.2), 1e-4);
  // The same camera turned in place: no parallax anywhere.
  const Camera turned = camera_from(Eigen::Vector3d::Zero(), Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix());
  EXPECT_LT(parallax_shift_px(depth, ref, {turned}, 0.1).max().item<float>(), 1e-4);
  // A source moved along the optical axis: no shift at the principal point, some at the edges.
  const Camera forward = camera_from(Eigen::Vector3d(0, 0, 0.1));
  const auto along = parallax_shift_px(depth, ref, {forward}, 0.1);
  EXPECT_LT(along[23][31].item<float>(), 0.01f);  // half a pixel off the principal point
  // The corner, 39.3 px from it: 39.3 (2 / 1.9 - 2.2 / 2.1) = 0.197 px.
  EXPECT_NEAR(along[0][0].item<float>(), 39.3 * (2 / 1.9 - 2.2 / 2.1), 2e-3);
  // The largest over several sources; pixels without depth have none.
  depth[0][0] = 0.0f;
  const auto both = parallax_shift_px(depth, ref, {turned, side}, 0.1);
  EXPECT_NEAR(both[23][31].item<float>(), shift[23][31].item<float>(), 1e-5);
  EXPECT_EQ(both[0][0].item<float>(), 0.0f);
  // Farther depth, less parallax (1/d).
  EXPECT_NEAR(parallax_shift_px(torch::full({48, 64}, 4.0f), ref, {side}, 0.1)[23][31].item<float>(),
              shift[23][31].item<float>() / 2, 1e-4);
  EXPECT_THROW(parallax_shift_px(torch::ones({4, 4}), ref, {side}), std::invalid_argument);
}

TEST(Parallax, TheEstimatorSettingIsValidated) {
  DepthEstimatorConfig config;
  config.min_parallax_px = -1.0;
  EXPECT_THROW(config.validate(), std::invalid_argument);
  config.min_parallax_px = 1.0;
  EXPECT_NO_THROW(config.validate());
}

}  // namespace
}  // namespace umvs
