#include "unsup_mvs/core/keyframes.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {

void KeyframeConfig::validate() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("keyframe config: " + what); };
  if (!std::isfinite(min_translation) || !std::isfinite(min_rotation_deg) || !std::isfinite(min_pose_distance)) {
    fail("thresholds must be finite");
  }
  if (min_translation <= 0 && min_rotation_deg <= 0 && min_pose_distance <= 0) {
    fail("at least one of min_translation, min_rotation_deg, min_pose_distance must be > 0");
  }
  if (num_sources < 1) fail("num_sources must be >= 1, got " + std::to_string(num_sources));
  if (lookahead < 0) fail("lookahead must be >= 0, got " + std::to_string(lookahead));
  if (!(std::isfinite(max_wait_s) && max_wait_s >= 0)) fail("max_wait_s must be >= 0, got " + std::to_string(max_wait_s));
  // A waiting reference must stay buffered until it is given up.
  if (buffer_size < num_sources + lookahead + 1) {
    fail("buffer_size must be at least num_sources + lookahead + 1 = " + std::to_string(num_sources + lookahead + 1) +
         ", got " + std::to_string(buffer_size));
  }
  if (score_grid < 2) fail("score_grid must be >= 2, got " + std::to_string(score_grid));
  if (!(min_score >= 0)) fail("min_score must be >= 0");
}

void KeyframeStreamConfig::validate() const {
  keyframes.validate();
  if (!(std::isfinite(depth_min) && std::isfinite(depth_max) && depth_min > 0 && depth_max > depth_min)) {
    throw std::invalid_argument("keyframe stream: need 0 < depth_min < depth_max, got " + std::to_string(depth_min) +
                                " .. " + std::to_string(depth_max));
  }
}

PoseDistance pose_distance(const Camera& a, const Camera& b) {
  const Eigen::Matrix4d rel = a.T_cam_world * b.T_world_cam();  // b's camera frame -> a's
  const Eigen::Matrix3d R = rel.topLeftCorner<3, 3>();
  PoseDistance d;
  d.translation = rel.topRightCorner<3, 1>().norm();
  const double trace = std::min(3.0, R.trace());
  d.rotation_deg = std::acos(std::clamp((trace - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
  d.combined = std::sqrt(d.translation * d.translation + 2.0 / 3.0 * (3.0 - trace));
  return d;
}

KeyframeBuffer::KeyframeBuffer(KeyframeConfig config) : config_(config) { config_.validate(); }

bool KeyframeBuffer::is_keyframe(const Camera& camera) const {
  if (keyframes_.empty()) return true;
  const PoseDistance d = pose_distance(keyframes_.back().camera, camera);
  return (config_.min_translation > 0 && d.translation >= config_.min_translation) ||
         (config_.min_rotation_deg > 0 && d.rotation_deg >= config_.min_rotation_deg) ||
         (config_.min_pose_distance > 0 && d.combined >= config_.min_pose_distance);
}

const Keyframe& KeyframeBuffer::add(const Camera& camera, double stamp, int64_t* evicted) {
  camera.validate("keyframe camera");
  if (evicted) *evicted = -1;
  keyframes_.push_back({next_id_++, stamp, camera});
  waiting_.push_back(keyframes_.back().id);
  if (static_cast<int>(keyframes_.size()) > config_.buffer_size) {
    if (evicted) *evicted = keyframes_.front().id;
    forget_waiting(keyframes_.front().id);
    keyframes_.pop_front();
  }
  return keyframes_.back();
}

void KeyframeBuffer::forget_waiting(int64_t id) {
  waiting_.erase(std::remove(waiting_.begin(), waiting_.end(), id), waiting_.end());
}

std::vector<ReferenceSources> KeyframeBuffer::take_ready_references(double depth, std::vector<int64_t>* given_up,
                                                                    std::optional<double> now) {
  return take_references(depth, given_up, [&](int64_t id, int64_t newer) {
    return newer >= config_.lookahead || waited_too_long(id, now);
  });
}

std::vector<ReferenceSources> KeyframeBuffer::take_waiting_references(double depth) {
  return take_references(depth, nullptr, [](int64_t, int64_t) { return true; });
}

std::vector<ReferenceSources> KeyframeBuffer::take_references(double depth, std::vector<int64_t>* given_up,
                                                              const std::function<bool(int64_t, int64_t)>& due) {
  std::vector<ReferenceSources> ready;
  const int64_t newest = next_id_ - 1;
  for (auto it = waiting_.begin(); it != waiting_.end();) {
    const int64_t id = *it;
    const int64_t newer = newest - id;  // ids are consecutive
    if (!due(id, newer)) {
      ++it;
      continue;
    }
    std::vector<KeyframeScore> sources = select_sources(id, depth);
    if (static_cast<int>(sources.size()) >= config_.num_sources) {
      ready.push_back({id, std::move(sources)});
      it = waiting_.erase(it);
    } else if (newer >= config_.lookahead + config_.num_sources) {
      if (given_up) given_up->push_back(id);
      it = waiting_.erase(it);
    } else {
      ++it;
    }
  }
  return ready;
}

bool KeyframeBuffer::waited_too_long(int64_t id, std::optional<double> now) const {
  if (!now || config_.max_wait_s <= 0) return false;
  const Keyframe* k = find(id);
  return k && *now - k->stamp >= config_.max_wait_s;
}

const Keyframe* KeyframeBuffer::find(int64_t id) const {
  for (const auto& k : keyframes_) {
    if (k.id == id) return &k;
  }
  return nullptr;
}

std::vector<KeyframeScore> KeyframeBuffer::select_sources(int64_t reference_id, double depth) const {
  const Keyframe* ref = find(reference_id);
  if (!ref) throw std::invalid_argument("keyframe " + std::to_string(reference_id) + " is not buffered");
  if (!(depth > 0)) throw std::invalid_argument("select_sources: depth must be > 0");
  return select_sources(reference_id, sample_frustum_points(ref->camera, depth, config_.score_grid));
}

std::vector<KeyframeScore> KeyframeBuffer::select_sources(int64_t reference_id,
                                                       const std::vector<Eigen::Vector3d>& points) const {
  const Keyframe* ref = find(reference_id);
  if (!ref) throw std::invalid_argument("keyframe " + std::to_string(reference_id) + " is not buffered");
  std::vector<Camera> cameras;
  std::vector<int64_t> ids;
  for (const auto& k : keyframes_) {
    if (k.id == reference_id) continue;
    cameras.push_back(k.camera);
    ids.push_back(k.id);
  }
  std::vector<KeyframeScore> best;
  for (const ScoredView& s : rank_source_views(points, ref->camera, cameras, config_.score)) {
    if (s.score < config_.min_score || static_cast<int>(best.size()) >= config_.num_sources) break;
    best.push_back({ids[s.index], s.score});
  }
  return best;
}

std::vector<int64_t> KeyframeBuffer::set_config(const KeyframeConfig& config) {
  config.validate();
  config_ = config;
  std::vector<int64_t> evicted;
  while (static_cast<int>(keyframes_.size()) > config_.buffer_size) {
    evicted.push_back(keyframes_.front().id);
    forget_waiting(keyframes_.front().id);
    keyframes_.pop_front();
  }
  return evicted;
}

void KeyframeBuffer::clear() {
  keyframes_.clear();
  waiting_.clear();
  next_id_ = 0;
}

std::vector<size_t> select_keyframes(const std::vector<Camera>& cameras, const KeyframeConfig& config) {
  KeyframeBuffer buffer(config);
  std::vector<size_t> chosen;
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (buffer.is_keyframe(cameras[i])) {
      buffer.add(cameras[i], static_cast<double>(i));
      chosen.push_back(i);
    }
  }
  return chosen;
}

bool depth_range_from_samples(std::vector<float> depths, double* near, double* far, double lo, double hi,
                              double margin, size_t min_count) {
  depths.erase(std::remove_if(depths.begin(), depths.end(), [](float d) { return !(std::isfinite(d) && d > 0); }),
               depths.end());
  if (depths.size() < std::max<size_t>(min_count, 1)) return false;
  auto at = [&](double q) {
    const size_t k = std::min(depths.size() - 1, static_cast<size_t>(q * (depths.size() - 1) + 0.5));
    std::nth_element(depths.begin(), depths.begin() + k, depths.end());
    return static_cast<double>(depths[k]);
  };
  const double a = at(lo), b = at(hi);
  *near = a / (1.0 + margin);
  *far = b * (1.0 + margin);
  return *far > *near;
}

}  // namespace umvs
