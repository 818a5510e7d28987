// Keyframe policy for a moving, posed camera (ROS-free; used by the keyframe_selector node and,
// offline, to build training tuples from logged sequences).
//
//  * A frame becomes a keyframe when the camera moved enough since the last keyframe: its
//    translation, its rotation, or the combined pose distance of DeepVideoMVS (Duzceker et al.
//    2021), d = sqrt(|t|^2 + 2/3 * trace(I - R)), where (R, t) is the relative pose, exceeds its
//    threshold (a threshold <= 0 is ignored).
//  * The buffer keeps the newest `buffer_size` keyframes.
//  * The neighbours of a reference are the buffered keyframes with the highest MVSNet
//    view-selection score (core/view_selection.h) on points sampled in the reference frustum.
//  * Every keyframe is a reference once. It waits for `lookahead` newer keyframes (so that they
//    can be its neighbours too: neighbours on both sides of it along the path see what one side
//    occludes) and, beyond that, until it has num_sources neighbours; a keyframe that still
//    has none after lookahead + num_sources newer ones is given up. With lookahead 0 a keyframe
//    is a reference as soon as it has its neighbours; the first keyframes of a run get theirs
//    from the keyframes after them. With the default, 1, the demo's fused rooms scored 4-6 F-score
//    points more than with the earlier policy (past neighbours only, the first keyframes
//    dropped; docs/results.md).
//  * A keyframe waits for its lookahead at most max_wait_s, measured by the stamps of the frames
//    that keep coming: a robot that stops still gets the depth of where it stands, from the
//    neighbours it has.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/view_selection.h"

namespace umvs {

struct KeyframeConfig {
  double min_translation = 0.10;   // metres; new keyframe when the camera moved at least this far
  double min_rotation_deg = 10.0;  // or turned at least this much
  double min_pose_distance = 0.0;  // or the combined DeepVideoMVS distance reaches this (0 = off)
  int buffer_size = 30;            // keyframes kept for neighbour selection
  int num_sources = 2;             // neighbours per reference
  int lookahead = 1;               // newer keyframes a reference waits for (latency in keyframes)
  double max_wait_s = 2.0;         // ... but no longer than this (stamps; 0 = as long as it takes)
  double min_score = 0.5;          // a neighbour needs at least this view-selection score
  int score_grid = 16;             // points per side sampled in the reference frustum
  ViewScoreConfig score;

  // Throws std::invalid_argument naming the bad field.
  void validate() const;
};

// How a calibrated, posed camera stream is read into keyframes: the one definition (and the one
// set of defaults) shared by the live keyframe_selector and by training on recorded bags
// (`umvs train --bag`, the trainer node), so that both see the same intrinsics and keyframes.
struct KeyframeStreamConfig {
  KeyframeConfig keyframes;
  bool rectified = true;    // intrinsics from CameraInfo P (a rectified image_rect* topic) or from K
  double depth_min = 0.3;   // metres: the plane-sweep range (live: until depth estimates narrow it)
  double depth_max = 10.0;

  // Throws std::invalid_argument naming the bad field.
  void validate() const;
};

struct PoseDistance {
  double translation = 0.0;   // metres
  double rotation_deg = 0.0;  // angle of the relative rotation
  double combined = 0.0;      // DeepVideoMVS: sqrt(|t|^2 + 2/3 trace(I - R))
};
// Distance between two camera poses (T_cam_world of each camera).
PoseDistance pose_distance(const Camera& a, const Camera& b);

struct Keyframe {
  int64_t id = 0;
  double stamp = 0.0;  // seconds
  Camera camera;
};

struct KeyframeScore {
  int64_t id = 0;      // keyframe id
  double score = 0.0;  // MVSNet view-selection score against the reference
};

// A reference keyframe and its neighbours, best first.
struct ReferenceSources {
  int64_t reference_id = 0;
  std::vector<KeyframeScore> sources;
};

class KeyframeBuffer {
 public:
  explicit KeyframeBuffer(KeyframeConfig config = {});

  // Whether a frame seen by `camera` moved far enough from the newest keyframe (true when empty).
  bool is_keyframe(const Camera& camera) const;
  // Appends a keyframe (ids increase from 0) and returns it; the oldest is evicted beyond
  // buffer_size, its id is written to *evicted (-1 when none). The camera must be valid.
  const Keyframe& add(const Camera& camera, double stamp, int64_t* evicted = nullptr);

  // The references that became ready (oldest first) and leave the waiting list: each waiting
  // keyframe with at least `lookahead` newer keyframes (or, given `now`, the stamp of the newest
  // frame, one at least max_wait_s older than it) and num_sources neighbours scoring >= min_score
  // on points sampled at `depth`. Waiting keyframes that got none after lookahead + num_sources
  // newer keyframes are given up; their ids go to *given_up.
  std::vector<ReferenceSources> take_ready_references(double depth, std::vector<int64_t>* given_up = nullptr,
                                                      std::optional<double> now = std::nullopt);
  // The end of a stream (a log that ended): every waiting keyframe that has num_sources
  // neighbours now is a reference, without waiting for its lookahead; the others keep waiting.
  std::vector<ReferenceSources> take_waiting_references(double depth);
  size_t waiting_references() const { return waiting_.size(); }

  // The best `num_sources` buffered keyframes for `reference_id` (best first), scored on points
  // sampled at `depth` in its frustum. Fewer when not enough keyframes score >= min_score.
  std::vector<KeyframeScore> select_sources(int64_t reference_id, double depth) const;
  // The same against surface points that are known (e.g. from a previous depth map).
  std::vector<KeyframeScore> select_sources(int64_t reference_id, const std::vector<Eigen::Vector3d>& points) const;

  const Keyframe* find(int64_t id) const;  // nullptr when not (or no longer) buffered
  const std::deque<Keyframe>& keyframes() const { return keyframes_; }
  const KeyframeConfig& config() const { return config_; }
  // A new policy for the frames from now on (live tuning). Throws std::invalid_argument naming
  // the field, keeping the old one. Beyond a smaller buffer_size the oldest keyframes are
  // dropped; their ids are returned.
  std::vector<int64_t> set_config(const KeyframeConfig& config);
  void clear();

 private:
  void forget_waiting(int64_t id);
  // Whether keyframe `id` has waited max_wait_s or longer for its lookahead by `now`.
  bool waited_too_long(int64_t id, std::optional<double> now) const;
  // Takes the waiting keyframes for which `due(id, newer keyframes)` holds and that have their
  // neighbours; gives up those that still have none after lookahead + num_sources newer ones.
  std::vector<ReferenceSources> take_references(double depth, std::vector<int64_t>* given_up,
                                                const std::function<bool(int64_t, int64_t)>& due);

  KeyframeConfig config_;
  std::deque<Keyframe> keyframes_;
  std::deque<int64_t> waiting_;  // keyframes not yet a reference, oldest first
  int64_t next_id_ = 0;
};

// Offline: indices of the frames of a sequence that the policy makes keyframes (the first frame
// always is one).
std::vector<size_t> select_keyframes(const std::vector<Camera>& cameras, const KeyframeConfig& config = {});

// A depth range [near, far] from observed depths (e.g. the previous depth map): the `lo`/`hi`
// percentiles of the finite positive values, widened by `margin` (near / (1 + margin),
// far * (1 + margin)). Returns false when fewer than `min_count` values are usable.
bool depth_range_from_samples(std::vector<float> depths, double* near, double* far, double lo = 0.02,
                              double hi = 0.98, double margin = 0.2, size_t min_count = 100);

}  // namespace umvs
