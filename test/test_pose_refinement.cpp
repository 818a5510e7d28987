#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <stdexcept>

#include "unsup_mvs/core/pose_refinement.h"

namespace umvs {
namespace {

constexpr double kRad = M_PI / 180.0;

// A ring of cameras looking at the origin, each with another roll.
std::map<int, Camera> ring_of_cameras(int count) {
  std::map<int, Camera> cameras;
  for (int k = 0; k < count; ++k) {
    const double azimuth = 0.25 * k;
    const Eigen::Vector3d centre(3.0 * std::sin(azimuth), 0.4 * k - 0.8, -3.0 * std::cos(azimuth));
    const Eigen::Vector3d forward = -centre.normalized();
    const Eigen::Vector3d right = Eigen::Vector3d::UnitY().cross(forward).normalized();
    Eigen::Matrix3d R_wc;
    R_wc << right, forward.cross(right), forward;
    R_wc = R_wc * Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    Camera c;
    c.width = 640;
    c.height = 480;
    c.K << 480, 0, 319.5, 0, 480, 239.5, 0, 0, 1;
    c.T_cam_world.topLeftCorner<3, 3>() = R_wc.transpose();
    c.T_cam_world.topRightCorner<3, 1>() = -R_wc.transpose() * centre;
    cameras[10 + k] = c;
  }
  return cameras;
}

Eigen::Vector3d rotation_vector(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

// The rotation taking camera `from`'s coordinates to camera `to`'s.
Eigen::Matrix3d relative(const Camera& from, const Camera& to) { return to.R() * from.R().transpose(); }

// The turn of `source` that gives it the relative orientation to `reference` (held as posed) that
// it has in `truth`: what a perfect pair measurement returns.
PairTurn exact_pair_turn(int reference, int source, const std::map<int, Camera>& posed, const std::map<int, Camera>& truth) {
  // turn * R_source R_reference^T = R_source_true R_reference_true^T
  const Eigen::Matrix3d turn = relative(truth.at(reference), truth.at(source)) * relative(posed.at(reference), posed.at(source)).transpose();
  return {reference, source, rotation_vector(turn) / kRad};
}

TEST(ConsistentViewTurns, RestoresTheRelativeOrientationsOfPosesOffByTenthsOfADegree) {
  const std::map<int, Camera> truth = ring_of_cameras(5);
  const std::map<int, Eigen::Vector3d> error_deg = {
      {10, {0.0, 0.0, 0.0}}, {11, {0.6, -0.5, 0.3}}, {12, {-0.4, 0.2, 0.7}}, {13, {0.3, 0.6, -0.2}}, {14, {-0.7, -0.3, 0.1}}};
  std::map<int, Camera> posed;
  for (const auto& [id, camera] : truth) posed[id] = camera.turned(error_deg.at(id) * kRad);
  // Each view against its two ring neighbours, as pair.txt would list them, in both directions.
  std::vector<PairTurn> measurements;
  for (int k = 10; k < 15; ++k) {
    for (const int other : {k - 1, k + 1}) {
      if (other >= 10 && other < 15) measurements.push_back(exact_pair_turn(k, other, posed, truth));
    }
  }
  const ConsistentTurns turns = consistent_view_turns(posed, measurements);
  ASSERT_EQ(turns.view_degrees.size(), 5u);
  ASSERT_EQ(turns.residual_degrees.size(), measurements.size());
  std::map<int, Camera> corrected;
  for (const auto& [id, camera] : posed) corrected[id] = camera.turned(turns.view_degrees.at(id) * kRad);
  // Every pair, measured or not, now has its true relative orientation, up to the small-angle
  // approximation (errors of the order of the square of the turns).
  for (int a = 10; a < 15; ++a) {
    for (int b = a + 1; b < 15; ++b) {
      const double before = rotation_vector(relative(posed[a], posed[b]) * relative(truth.at(a), truth.at(b)).transpose()).norm() / kRad;
      const double after = rotation_vector(relative(corrected[a], corrected[b]) * relative(truth.at(a), truth.at(b)).transpose()).norm() / kRad;
      EXPECT_LT(after, 0.02) << "views " << a << " and " << b << " were " << before << " degrees off";
      EXPECT_GT(before, 0.3);
    }
  }
  for (const double r : turns.residual_degrees) EXPECT_LT(r, 0.02);
  // Of all solutions, the smallest: the turns' mean in the world frame is zero.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [id, d] : turns.view_degrees) mean += posed.at(id).R().transpose() * d / 5.0;
  EXPECT_LT(mean.norm(), 1e-9);
}

TEST(ConsistentViewTurns, KeepsPosesWithoutEvidenceAndSaysWhichMeasurementDisagrees) {
  const std::map<int, Camera> cameras = ring_of_cameras(4);
  // No measurement, or measurements that all say "as posed": nothing turns.
  for (const auto& measurements : {std::vector<PairTurn>{}, std::vector<PairTurn>{{10, 11, {0, 0, 0}}, {12, 13, {0, 0, 0}}}}) {
    const ConsistentTurns turns = consistent_view_turns(cameras, measurements);
    for (const auto& [id, d] : turns.view_degrees) EXPECT_EQ(d.norm(), 0.0) << "view " << id;
  }
  // Three views in a loop: two pairs say "as posed", the third says 0.9 degrees. No solution
  // fits all three; the least-squares one spreads the disagreement over the loop.
  const ConsistentTurns loop = consistent_view_turns(cameras, {{10, 11, {0, 0, 0}}, {11, 12, {0, 0, 0}}, {10, 12, {0.9, 0, 0}}});
  ASSERT_EQ(loop.residual_degrees.size(), 3u);
  for (const double r : loop.residual_degrees) EXPECT_NEAR(r, 0.3, 1e-6);
  EXPECT_EQ(loop.view_degrees.at(13).norm(), 0.0) << "a view no measurement names keeps its pose";
}

TEST(ConsistentViewTurns, RefusesMeasurementsItCannotUse) {
  const std::map<int, Camera> cameras = ring_of_cameras(2);
  EXPECT_THROW(consistent_view_turns(cameras, {{10, 99, {0.1, 0, 0}}}), std::invalid_argument);
  EXPECT_THROW(consistent_view_turns(cameras, {{10, 10, {0.1, 0, 0}}}), std::invalid_argument);
  EXPECT_THROW(consistent_view_turns(cameras, {{10, 11, {std::nan(""), 0, 0}}}), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
