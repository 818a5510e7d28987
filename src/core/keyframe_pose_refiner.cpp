#include "unsup_mvs/core/keyframe_pose_refiner.h"

#include <cmath>
#include <set>
#include <stdexcept>
#include <string>

namespace umvs {

namespace {

// Whether two cameras are the same pose and calibration, up to rounding on the way through messages.
bool same_camera(const Camera& a, const Camera& b) {
  constexpr double kTolerance = 1e-7;
  return a.width == b.width && a.height == b.height && (a.K - b.K).cwiseAbs().maxCoeff() < kTolerance &&
         (a.T_cam_world - b.T_cam_world).cwiseAbs().maxCoeff() < kTolerance;
}

}  // namespace

std::optional<Eigen::Vector3d> measured_pair_turn(const SourceTurn& turn) {
  if (turn.kept) return turn.degrees;
  if (turn.search_gain < kMinSourceTurnGain) return Eigen::Vector3d::Zero();
  return std::nullopt;
}

void KeyframePoseRefinerConfig::validate() const {
  if (!std::isfinite(search_deg) || search_deg <= 0) {
    throw std::invalid_argument("pose refinement: search_deg must be an angle > 0 degrees, got " + std::to_string(search_deg));
  }
  if (max_keyframes < 2) {
    throw std::invalid_argument("pose refinement: max_keyframes must be at least 2, got " + std::to_string(max_keyframes));
  }
}

KeyframePoseRefiner::KeyframePoseRefiner(KeyframePoseRefinerConfig config) : config_(config) { config_.validate(); }

Eigen::Vector3d KeyframePoseRefiner::turn_degrees(int64_t id) const {
  const auto it = keyframes_.find(id);
  return it == keyframes_.end() ? Eigen::Vector3d::Zero() : it->second.turn_degrees;
}

void KeyframePoseRefiner::forget(int64_t id) {
  keyframes_.erase(id);
  for (auto it = pairs_.begin(); it != pairs_.end();) {
    it = it->first.first == id || it->first.second == id ? pairs_.erase(it) : std::next(it);
  }
}

void KeyframePoseRefiner::solve() {
  // consistent_view_turns names views by int: number the keyframes densely.
  std::map<int64_t, int> index;
  std::map<int, Camera> cameras;
  for (const auto& [id, keyframe] : keyframes_) {
    const int i = static_cast<int>(index.size());
    index.emplace(id, i);
    cameras.emplace(i, keyframe.given);
  }
  std::vector<PairTurn> measurements;
  for (const auto& [pair, turn] : pairs_) {
    if (turn) measurements.push_back({index.at(pair.first), index.at(pair.second), *turn});
  }
  const ConsistentTurns turns = consistent_view_turns(cameras, measurements);
  for (auto& [id, keyframe] : keyframes_) keyframe.turn_degrees = turns.view_degrees.at(index.at(id));
}

std::vector<ViewInput> KeyframePoseRefiner::correct(DepthEstimator& estimator, const std::vector<int64_t>& ids,
                                                    std::vector<ViewInput> views, double depth_min, double depth_max) {
  if (ids.size() != views.size()) {
    throw std::invalid_argument("pose refinement: " + std::to_string(ids.size()) + " keyframe ids for " +
                                std::to_string(views.size()) + " views");
  }
  if (views.size() > config_.max_keyframes) {  // it would forget its own keyframes
    throw std::invalid_argument("pose refinement: a set of " + std::to_string(views.size()) + " views, more than the " +
                                std::to_string(config_.max_keyframes) + " keyframes it remembers");
  }
  if (std::set<int64_t>(ids.begin(), ids.end()).size() != ids.size()) {
    throw std::invalid_argument("pose refinement: a keyframe id appears twice in one set");
  }
  // Measure first, into a scratch list: a view the estimator refuses leaves nothing behind.
  std::vector<std::pair<std::pair<int64_t, int64_t>, std::optional<Eigen::Vector3d>>> measured;
  const auto known = [&](size_t i) {
    const auto it = keyframes_.find(ids[i]);
    return it != keyframes_.end() && same_camera(it->second.given, views[i].camera);
  };
  for (size_t s = 1; s < views.size(); ++s) {
    const std::pair<int64_t, int64_t> pair{ids[0], ids[s]};
    if (known(0) && known(s) && pairs_.count(pair)) continue;
    const SourceTurn turn = estimator.best_source_turn(views[0], views[s], depth_min, depth_max, config_.search_deg);
    measured.emplace_back(pair, measured_pair_turn(turn));
  }
  last_new_measurements_ = static_cast<int>(measured.size());

  ++clock_;
  for (size_t i = 0; i < views.size(); ++i) {
    if (!known(i)) forget(ids[i]);  // new, or moved since its pairs were measured
    Keyframe& keyframe = keyframes_[ids[i]];
    keyframe.given = views[i].camera;
    keyframe.last_used = clock_;
  }
  for (auto& [pair, turn] : measured) pairs_[pair] = turn;
  while (keyframes_.size() > config_.max_keyframes) {
    auto oldest = keyframes_.begin();
    for (auto it = keyframes_.begin(); it != keyframes_.end(); ++it) {
      if (it->second.last_used < oldest->second.last_used) oldest = it;
    }
    forget(oldest->first);
  }
  if (!measured.empty()) solve();
  for (size_t i = 0; i < views.size(); ++i) {
    views[i].camera = views[i].camera.turned(turn_degrees(ids[i]) * kRadiansPerDegree);
  }
  return views;
}

}  // namespace umvs
