#include "unsup_mvs/core/pose_refinement.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {

namespace {
constexpr double kDegreesPerRadian = 180.0 / M_PI;
}  // namespace

ConsistentTurns consistent_view_turns(const std::map<int, Camera>& cameras, const std::vector<PairTurn>& measurements) {
  std::map<int, int> column;  // view id -> index of its 3 unknowns
  for (const auto& [id, camera] : cameras) column.emplace(id, static_cast<int>(column.size()));
  for (const PairTurn& m : measurements) {
    for (const int id : {m.reference, m.source}) {
      if (!column.count(id)) throw std::invalid_argument("a pair turn names view " + std::to_string(id) + ", which has no camera");
    }
    if (m.reference == m.source) throw std::invalid_argument("a pair turn of view " + std::to_string(m.source) + " with itself");
    if (!m.degrees.allFinite()) {
      throw std::invalid_argument("the turn of view " + std::to_string(m.source) + " against " + std::to_string(m.reference) +
                                  " is not finite");
    }
  }
  // Camera::turned(a) maps camera coordinates by exp(a), i.e. R_cw' = exp(a) R_cw = R_cw exp(R_wc a).
  // With each view's turn written in the world frame, g = R_wc a, the relative rotation of a pair
  // changes by exp(g_source - g_reference) to first order, and the measurement holds g_reference
  // at zero: g_source - g_reference = R_wc(source) a_measured.
  const int n = static_cast<int>(column.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3 * static_cast<Eigen::Index>(measurements.size()), 3 * n);
  Eigen::VectorXd b(A.rows());
  for (size_t k = 0; k < measurements.size(); ++k) {
    const PairTurn& m = measurements[k];
    const auto row = static_cast<Eigen::Index>(3 * k);
    A.block<3, 3>(row, 3 * column.at(m.source)) = Eigen::Matrix3d::Identity();
    A.block<3, 3>(row, 3 * column.at(m.reference)) = -Eigen::Matrix3d::Identity();
    b.segment<3>(row) = cameras.at(m.source).R().transpose() * (m.degrees / kDegreesPerRadian);
  }
  // The minimum-norm least-squares solution: a common turn of all views is in A's null space.
  const Eigen::VectorXd g = measurements.empty() ? Eigen::VectorXd::Zero(3 * n)
                                                  : Eigen::VectorXd(A.completeOrthogonalDecomposition().solve(b));
  ConsistentTurns out;
  for (const auto& [id, index] : column) {
    out.view_degrees[id] = cameras.at(id).R() * g.segment<3>(3 * index) * kDegreesPerRadian;
  }
  const Eigen::VectorXd residual = A * g - b;
  for (size_t k = 0; k < measurements.size(); ++k) {
    out.residual_degrees.push_back(residual.segment<3>(static_cast<Eigen::Index>(3 * k)).norm() * kDegreesPerRadian);
  }
  return out;
}

}  // namespace umvs
