#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "unsup_mvs/core/keyframes.h"

namespace umvs {
namespace {

// A 160x128 camera at `center` looking along +z of the world (identity rotation) or turned by
// `yaw_deg` about the camera's y axis.
Camera camera_at(const Eigen::Vector3d& center, double yaw_deg = 0.0) {
  Camera c;
  c.width = 160;
  c.height = 128;
  c.K << 120, 0, 79.5, 0, 120, 63.5, 0, 0, 1;
  const Eigen::Matrix3d R_world_cam = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Eigen::Matrix4d T_world_cam = Eigen::Matrix4d::Identity();
  T_world_cam.topLeftCorner<3, 3>() = R_world_cam;
  T_world_cam.topRightCorner<3, 1>() = center;
  c.T_cam_world = T_world_cam.inverse();
  return c;
}

TEST(Keyframes, PoseDistanceMatchesDefinition) {
  const PoseDistance same = pose_distance(camera_at({1, 2, 3}, 20), camera_at({1, 2, 3}, 20));
  EXPECT_NEAR(same.translation, 0.0, 1e-12);
  EXPECT_NEAR(same.rotation_deg, 0.0, 1e-6);
  EXPECT_NEAR(same.combined, 0.0, 1e-6);

  const PoseDistance moved = pose_distance(camera_at({0, 0, 0}), camera_at({0.3, 0.4, 0}));
  EXPECT_NEAR(moved.translation, 0.5, 1e-12);
  EXPECT_NEAR(moved.rotation_deg, 0.0, 1e-6);
  EXPECT_NEAR(moved.combined, 0.5, 1e-9);

  // A pure rotation by 30 degrees: trace(R) = 1 + 2 cos(30deg).
  const PoseDistance turned = pose_distance(camera_at({0, 0, 0}), camera_at({0, 0, 0}, 30));
  EXPECT_NEAR(turned.translation, 0.0, 1e-12);
  EXPECT_NEAR(turned.rotation_deg, 30.0, 1e-9);
  EXPECT_NEAR(turned.combined, std::sqrt(2.0 / 3.0 * (2.0 - 2.0 * std::cos(M_PI / 6))), 1e-9);
}

TEST(Keyframes, NewKeyframeOnlyAfterEnoughMotion) {
  KeyframeConfig cfg;
  cfg.min_translation = 0.1;
  cfg.min_rotation_deg = 10.0;
  KeyframeBuffer buffer(cfg);
  EXPECT_TRUE(buffer.is_keyframe(camera_at({0, 0, 0})));
  buffer.add(camera_at({0, 0, 0}), 0.0);
  EXPECT_FALSE(buffer.is_keyframe(camera_at({0.05, 0, 0})));
  EXPECT_FALSE(buffer.is_keyframe(camera_at({0, 0, 0}, 5)));
  EXPECT_TRUE(buffer.is_keyframe(camera_at({0.1, 0, 0})));
  EXPECT_TRUE(buffer.is_keyframe(camera_at({0, 0, 0}, 11)));

  // The combined distance alone: 0.08 m and 6 degrees are each below their thresholds but
  // sqrt(0.08^2 + 2/3 * (2 - 2 cos 6deg)) = 0.117 is above 0.1.
  cfg.min_translation = 0;
  cfg.min_rotation_deg = 0;
  cfg.min_pose_distance = 0.1;
  KeyframeBuffer combined(cfg);
  combined.add(camera_at({0, 0, 0}), 0.0);
  EXPECT_FALSE(combined.is_keyframe(camera_at({0.08, 0, 0})));
  EXPECT_TRUE(combined.is_keyframe(camera_at({0.08, 0, 0}, 6)));
}

TEST(Keyframes, BufferIsBoundedAndEvictsTheOldest) {
  KeyframeConfig cfg;
  cfg.buffer_size = 4;
  KeyframeBuffer buffer(cfg);
  int64_t evicted = 0;
  for (int i = 0; i < 6; ++i) {
    const Keyframe& k = buffer.add(camera_at({0.2 * i, 0, 0}), i, &evicted);
    EXPECT_EQ(k.id, i);
    EXPECT_EQ(evicted, i < 4 ? -1 : i - 4);
  }
  EXPECT_EQ(buffer.keyframes().size(), 4u);
  EXPECT_EQ(buffer.keyframes().front().id, 2);
  EXPECT_EQ(buffer.find(1), nullptr);
  ASSERT_NE(buffer.find(5), nullptr);
  EXPECT_DOUBLE_EQ(buffer.find(5)->stamp, 5.0);
}

TEST(Keyframes, NewPolicyAppliesToTheNextFrame) {
  KeyframeConfig cfg;
  cfg.min_translation = 0.1;
  cfg.buffer_size = 6;
  KeyframeBuffer buffer(cfg);
  for (int i = 0; i < 5; ++i) buffer.add(camera_at({0.2 * i, 0, 0}), i);
  EXPECT_TRUE(buffer.is_keyframe(camera_at({0.95, 0, 0})));

  KeyframeConfig bad = cfg;
  bad.buffer_size = bad.num_sources;  // needs num_sources + lookahead + 1
  EXPECT_THROW(buffer.set_config(bad), std::invalid_argument);
  EXPECT_EQ(buffer.config().buffer_size, 6);
  EXPECT_EQ(buffer.keyframes().size(), 5u);

  KeyframeConfig wider = cfg;
  wider.min_translation = 0.3;
  wider.buffer_size = 3;
  wider.lookahead = 0;  // 3 = num_sources + lookahead + 1
  EXPECT_EQ(buffer.set_config(wider), (std::vector<int64_t>{0, 1}));  // the oldest go
  EXPECT_EQ(buffer.keyframes().size(), 3u);
  EXPECT_EQ(buffer.keyframes().front().id, 2);
  EXPECT_FALSE(buffer.is_keyframe(camera_at({0.95, 0, 0})));  // 0.15 m from the last one now too little
  EXPECT_TRUE(buffer.is_keyframe(camera_at({1.2, 0, 0})));
}

TEST(Keyframes, NeighboursAreTheBestTriangulatingViews) {
  // Reference at the origin looking at a surface 2 m away. The view-selection score peaks at a
  // 5 degree triangulation angle: a baseline of ~0.175 m at 2 m. Candidates: 0.02 m (angle too
  // small), 0.17 m and -0.18 m (both near optimal), 1.5 m (too wide), and one turned away.
  KeyframeConfig cfg;
  cfg.min_translation = 0.01;
  KeyframeBuffer buffer(cfg);
  buffer.add(camera_at({0.02, 0, 0}), 0);    // id 0
  buffer.add(camera_at({1.5, 0, 0}), 1);     // id 1
  buffer.add(camera_at({0.17, 0, 0}), 2);    // id 2
  buffer.add(camera_at({0, 0, 0}, 180), 3);  // id 3: sees nothing of the reference's surface
  buffer.add(camera_at({-0.18, 0, 0}), 4);   // id 4
  const Keyframe& ref = buffer.add(camera_at({0, 0, 0}), 5);
  const auto best = buffer.select_sources(ref.id, 2.0);
  ASSERT_EQ(best.size(), 2u);
  EXPECT_TRUE((best[0].id == 2 && best[1].id == 4) || (best[0].id == 4 && best[1].id == 2))
      << best[0].id << ", " << best[1].id;
  EXPECT_GE(best[0].score, best[1].score);

  // With only poor candidates, fewer neighbours than asked are returned.
  KeyframeConfig strict = cfg;
  strict.min_score = 100.0;  // out of 256 sampled points
  KeyframeBuffer poor(strict);
  poor.add(camera_at({0.02, 0, 0}), 0);
  poor.add(camera_at({0, 0, 0}, 180), 1);
  const Keyframe& r = poor.add(camera_at({0, 0, 0}), 2);
  EXPECT_TRUE(poor.select_sources(r.id, 2.0).empty());
  EXPECT_THROW(poor.select_sources(99, 2.0), std::invalid_argument);
}

// Ids of the references taken after each added keyframe, e.g. {{}, {}, {0, 1, 2}, {3}}.
std::vector<std::vector<int64_t>> references_while_adding(KeyframeBuffer& buffer, const std::vector<Camera>& cameras,
                                                          std::vector<ReferenceSources>* all = nullptr,
                                                          std::vector<int64_t>* given_up = nullptr) {
  std::vector<std::vector<int64_t>> taken;
  for (size_t i = 0; i < cameras.size(); ++i) {
    buffer.add(cameras[i], static_cast<double>(i));
    taken.emplace_back();
    for (auto& r : buffer.take_ready_references(2.0, given_up)) {
      taken.back().push_back(r.reference_id);
      if (all) all->push_back(std::move(r));
    }
  }
  return taken;
}

// A camera driving sideways `step` m per keyframe in front of a wall 2 m away. The view score
// peaks at a 5 degree triangulation angle and falls steeply below it; at the frustum's edges
// a baseline triangulates at cos^2(33 deg) = 0.7 of its angle at the centre.
std::vector<Camera> sideways_drive(int n, double step = 0.09) {
  std::vector<Camera> cameras;
  for (int i = 0; i < n; ++i) cameras.push_back(camera_at({step * i, 0, 0}));
  return cameras;
}

TEST(Keyframes, EveryKeyframeBecomesAReferenceOnce) {
  // Without lookahead a keyframe is a reference as soon as it has two neighbours: the first two
  // wait for the third keyframe and then use the keyframes after them.
  KeyframeConfig cfg;
  cfg.lookahead = 0;
  KeyframeBuffer buffer(cfg);
  std::vector<ReferenceSources> sets;
  const auto taken = references_while_adding(buffer, sideways_drive(5), &sets);
  EXPECT_EQ(taken, (std::vector<std::vector<int64_t>>{{}, {}, {0, 1, 2}, {3}, {4}}));
  ASSERT_EQ(sets.size(), 5u);
  for (const auto& s : sets) {
    ASSERT_EQ(s.sources.size(), 2u) << "reference " << s.reference_id;
    for (const auto& n : s.sources) {
      EXPECT_NE(n.id, s.reference_id);
      EXPECT_LE(n.id, std::max<int64_t>(s.reference_id, 2)) << "a neighbour from after the set was published";
    }
  }
  EXPECT_EQ(buffer.waiting_references(), 0u);
}

TEST(Keyframes, LookaheadGivesNeighboursOnBothSides) {
  // 0.3 m per keyframe (6-9 degrees over the frustum; k +- 2 at 12-17): the best neighbours of
  // keyframe k are k - 1 and k + 1.
  KeyframeConfig cfg;  // lookahead 1, the default
  ASSERT_EQ(cfg.lookahead, 1);
  KeyframeBuffer buffer(cfg);
  std::vector<ReferenceSources> sets;
  const auto taken = references_while_adding(buffer, sideways_drive(6, 0.3), &sets);
  // A reference waits for one newer keyframe; the newest one is still waiting at the end.
  EXPECT_EQ(taken, (std::vector<std::vector<int64_t>>{{}, {}, {0, 1}, {2}, {3}, {4}}));
  EXPECT_EQ(buffer.waiting_references(), 1u);
  for (const auto& s : sets) {
    if (s.reference_id == 0) continue;  // nothing before it
    ASSERT_EQ(s.sources.size(), 2u);
    EXPECT_EQ(std::min(s.sources[0].id, s.sources[1].id), s.reference_id - 1);
    EXPECT_EQ(std::max(s.sources[0].id, s.sources[1].id), s.reference_id + 1);
  }

  // Invalid: negative, or a buffer too small to keep a waiting reference until it is given up.
  KeyframeConfig bad = cfg;
  bad.lookahead = -1;
  EXPECT_THROW(KeyframeBuffer{bad}, std::invalid_argument);
  bad = cfg;
  bad.buffer_size = cfg.num_sources + cfg.lookahead;  // needs one more
  EXPECT_THROW(KeyframeBuffer{bad}, std::invalid_argument);
}

TEST(Keyframes, AKeyframeWaitsForItsLookaheadAtMostMaxWait) {
  // A robot that stops: its newest keyframe gets no newer one to wait for. The frames that keep
  // coming (their stamps as `now`) release it max_wait_s after it was taken, with the neighbours
  // it has (the keyframes before it).
  KeyframeConfig cfg;  // lookahead 1, max_wait_s 2, the defaults
  ASSERT_EQ(cfg.max_wait_s, 2.0);
  KeyframeBuffer buffer(cfg);
  references_while_adding(buffer, sideways_drive(4, 0.3));  // keyframe k at stamp k
  ASSERT_EQ(buffer.waiting_references(), 1u);
  EXPECT_TRUE(buffer.take_ready_references(2.0).empty()) << "no clock: it waits for a newer keyframe";
  EXPECT_TRUE(buffer.take_ready_references(2.0, nullptr, 4.99).empty()) << "1.99 s after keyframe 3";
  const auto released = buffer.take_ready_references(2.0, nullptr, 5.0);
  ASSERT_EQ(released.size(), 1u);
  EXPECT_EQ(released[0].reference_id, 3);
  ASSERT_EQ(released[0].sources.size(), 2u);
  EXPECT_EQ(std::max(released[0].sources[0].id, released[0].sources[1].id), 2) << "the neighbours before it";
  EXPECT_EQ(buffer.waiting_references(), 0u);
  EXPECT_TRUE(buffer.take_ready_references(2.0, nullptr, 9.0).empty()) << "a keyframe is a reference once";

  // The next keyframe is waited for as before; a stamp older than a keyframe releases nothing.
  buffer.add(camera_at({1.2, 0, 0}), 9.0);
  EXPECT_TRUE(buffer.take_ready_references(2.0, nullptr, 10.0).empty());
  EXPECT_TRUE(buffer.take_ready_references(2.0, nullptr, 3.0).empty());

  // max_wait_s 0: the lookahead is waited for however long it takes.
  KeyframeConfig patient = cfg;
  patient.max_wait_s = 0;
  KeyframeBuffer forever(patient);
  references_while_adding(forever, sideways_drive(4, 0.3));
  EXPECT_TRUE(forever.take_ready_references(2.0, nullptr, 1e6).empty());
  EXPECT_EQ(forever.waiting_references(), 1u);

  // A keyframe without neighbours keeps waiting at rest; it is not given up for the time.
  KeyframeBuffer alone(cfg);
  alone.add(camera_at({0, 0, 0}), 0.0);
  std::vector<int64_t> given_up;
  EXPECT_TRUE(alone.take_ready_references(2.0, &given_up, 100.0).empty());
  EXPECT_TRUE(given_up.empty());
  EXPECT_EQ(alone.waiting_references(), 1u);

  for (const double bad_wait : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    KeyframeConfig bad = cfg;
    bad.max_wait_s = bad_wait;
    EXPECT_THROW(KeyframeBuffer{bad}, std::invalid_argument) << bad_wait;
  }
}

TEST(Keyframes, AtTheEndOfAStreamWaitingKeyframesWithNeighboursAreTaken) {
  // A log that ends: no frame comes to release the newest keyframe. take_waiting_references
  // sends it with the neighbours it has, even with max_wait_s 0; one without neighbours stays.
  KeyframeConfig cfg;
  cfg.max_wait_s = 0;
  KeyframeBuffer buffer(cfg);
  std::vector<Camera> cameras = sideways_drive(5, 0.15);
  cameras[3] = camera_at({0.45, 0, 0}, 180);  // looks the other way: nobody shares its view
  references_while_adding(buffer, cameras);
  ASSERT_EQ(buffer.waiting_references(), 2u) << "keyframe 3 (no neighbours) and 4 (its lookahead)";
  const auto last = buffer.take_waiting_references(2.0);
  ASSERT_EQ(last.size(), 1u);
  EXPECT_EQ(last[0].reference_id, 4);
  ASSERT_EQ(last[0].sources.size(), 2u);
  for (const auto& n : last[0].sources) EXPECT_LT(n.id, 3);
  EXPECT_EQ(buffer.waiting_references(), 1u);
  EXPECT_TRUE(buffer.take_waiting_references(2.0).empty());
}

TEST(Keyframes, AKeyframeWithoutNeighboursIsGivenUp) {
  // The fourth keyframe looks the other way: nobody shares its view, so after num_sources newer
  // keyframes it stops waiting; the others still become references.
  KeyframeConfig cfg;
  cfg.lookahead = 0;
  KeyframeBuffer buffer(cfg);
  std::vector<Camera> cameras = sideways_drive(6);
  cameras[3] = camera_at({0.27, 0, 0}, 180);
  std::vector<int64_t> given_up;
  std::vector<ReferenceSources> sets;
  references_while_adding(buffer, cameras, &sets, &given_up);
  EXPECT_EQ(given_up, (std::vector<int64_t>{3}));
  std::vector<int64_t> references;
  for (const auto& s : sets) {
    references.push_back(s.reference_id);
    for (const auto& n : s.sources) EXPECT_NE(n.id, 3) << "the turned keyframe as a neighbour of " << s.reference_id;
  }
  EXPECT_EQ(references, (std::vector<int64_t>{0, 1, 2, 4, 5}));
  EXPECT_EQ(buffer.waiting_references(), 0u);
}

TEST(Keyframes, OfflineSelectionOnATrajectory) {
  // 1.01 cm per frame along x: with a 10 cm threshold every 10th frame is a keyframe.
  std::vector<Camera> traj;
  for (int i = 0; i < 50; ++i) traj.push_back(camera_at({0.0101 * i, 0, 0}));
  const auto chosen = select_keyframes(traj);
  ASSERT_EQ(chosen.size(), 5u);
  for (size_t k = 0; k < chosen.size(); ++k) EXPECT_EQ(chosen[k], 10 * k);
}

TEST(Keyframes, InvalidConfigAndCameraAreRefused) {
  KeyframeConfig cfg;
  cfg.buffer_size = 3;  // needs num_sources + lookahead + 1 = 4
  EXPECT_THROW(KeyframeBuffer{cfg}, std::invalid_argument);
  cfg = {};
  cfg.min_translation = cfg.min_rotation_deg = cfg.min_pose_distance = 0;
  EXPECT_THROW(KeyframeBuffer{cfg}, std::invalid_argument);
  KeyframeBuffer buffer;
  Camera bad = camera_at({0, 0, 0});
  bad.T_cam_world(0, 3) = std::nan("");
  EXPECT_THROW(buffer.add(bad, 0), std::invalid_argument);
  EXPECT_TRUE(buffer.keyframes().empty());
}

TEST(Keyframes, DepthRangeFromSamples) {
  std::vector<float> d;
  for (int i = 0; i <= 1000; ++i) d.push_back(1.0f + 0.003f * i);  // 1 .. 4 m
  d.push_back(std::nanf(""));
  d.push_back(-1.0f);
  double near = 0, far = 0;
  ASSERT_TRUE(depth_range_from_samples(d, &near, &far, 0.0, 1.0, 0.0));
  EXPECT_NEAR(near, 1.0, 1e-6);
  EXPECT_NEAR(far, 4.0, 1e-5);
  ASSERT_TRUE(depth_range_from_samples(d, &near, &far, 0.1, 0.9, 0.25));
  EXPECT_NEAR(near, 1.3 / 1.25, 1e-3);
  EXPECT_NEAR(far, 3.7 * 1.25, 1e-3);
  EXPECT_FALSE(depth_range_from_samples({1.0f, 2.0f}, &near, &far));
}

}  // namespace
}  // namespace umvs
