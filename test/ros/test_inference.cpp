// rostest for the inference node: lazy subscription, reload_model (refuses a corrupt checkpoint and
// keeps the old model), DepthEstimate outputs (stamps, frames, sizes, intrinsics, ranges), bad
// keyframe sets (unsupported encoding, NaN pose, impossible depth range) logged and skipped, and
// latest-wins when sets arrive faster than the network runs, with ~stats accounting for every set,
// and a fine pass's half-resolution maps.
#include <torch/torch.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include <std_srvs/Trigger.h>

#include "rostest_util.h"
#include "test_messages.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/io/checkpoint.h"

namespace {

using umvs_test::wait_for;
constexpr int kWidth = 128, kHeight = 96;
constexpr double kFocal = 100.0;

unsup_mvs::KeyframeSet make_set(uint32_t id) { return umvs_test::keyframe_set(id, {kWidth, kHeight, kFocal, "cam"}); }

class InferenceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = umvs_test::temp_dir("inference");
    torch::manual_seed(0);
    umvs::MvsNet net(umvs::MvsNetConfig{});
    umvs::save_checkpoint(dir_ + "/model.pt", net);
    std::ofstream(dir_ + "/corrupt.pt") << "this is not a checkpoint";
  }

  void SetUp() override {
    keyframes_pub_ = nh_.advertise<unsup_mvs::KeyframeSet>("/keyframes", 10);
    reload_ = nh_.serviceClient<unsup_mvs::ReloadModel>("/inference/reload_model");
    ASSERT_TRUE(reload_.waitForExistence(ros::Duration(30.0))) << "inference did not come up";
  }

  void subscribe() {
    estimate_sub_ = nh_.subscribe("/depth_estimate", 10, &InferenceTest::onEstimate, this);
    depth_sub_ = nh_.subscribe("/depth", 10, &InferenceTest::onDepth, this);
    ASSERT_TRUE(wait_for([&] { return keyframes_pub_.getNumSubscribers() > 0; }, 10.0));
  }
  void onEstimate(const unsup_mvs::DepthEstimateConstPtr& m) { estimates_.push_back(m); }
  void onDepth(const sensor_msgs::ImageConstPtr& m) { depth_images_.push_back(m); }

  bool reload(const std::string& path, std::string* message) {
    unsup_mvs::ReloadModel srv;
    srv.request.checkpoint = path;
    EXPECT_TRUE(reload_.call(srv));
    *message = srv.response.message;
    return srv.response.success;
  }

  // One of inference.test's other nodes, on topics under /<topics>/: its keyframes publisher, the
  // estimates it sends (into *got), the test model loaded. Fails the test when it does not come up.
  ros::Publisher connect(const std::string& node, const std::string& topics, ros::Subscriber* sub,
                         std::vector<unsup_mvs::DepthEstimateConstPtr>* got) {
    ros::Publisher pub = nh_.advertise<unsup_mvs::KeyframeSet>("/" + topics + "/keyframes", 10);
    ros::ServiceClient reload = nh_.serviceClient<unsup_mvs::ReloadModel>("/" + node + "/reload_model");
    EXPECT_TRUE(reload.waitForExistence(ros::Duration(30.0))) << node << " did not come up";
    *sub = nh_.subscribe<unsup_mvs::DepthEstimate>("/" + topics + "/depth_estimate", 10,
                                                   [got](const unsup_mvs::DepthEstimateConstPtr& m) { got->push_back(m); });
    EXPECT_TRUE(wait_for([&] { return pub.getNumSubscribers() > 0; }, 10.0));
    unsup_mvs::ReloadModel srv;
    srv.request.checkpoint = dir_ + "/model.pt";
    EXPECT_TRUE(reload.call(srv) && srv.response.success) << srv.response.message;
    return pub;
  }

  static std::string dir_;
  ros::NodeHandle nh_;
  ros::Publisher keyframes_pub_;
  ros::ServiceClient reload_;
  ros::Subscriber estimate_sub_, depth_sub_;
  std::vector<unsup_mvs::DepthEstimateConstPtr> estimates_;
  std::vector<sensor_msgs::ImageConstPtr> depth_images_;
};
std::string InferenceTest::dir_;

TEST_F(InferenceTest, SubscribesLazily) {
  // Once its services are up the nodelet is initialised: it must still not listen to keyframes.
  ASSERT_TRUE(reload_.waitForExistence(ros::Duration(30.0)));
  ros::spinOnce();
  EXPECT_EQ(keyframes_pub_.getNumSubscribers(), 0u) << "keyframes subscribed without anyone listening to the outputs";
  subscribe();
  EXPECT_EQ(keyframes_pub_.getNumSubscribers(), 1u);
  estimate_sub_.shutdown();
  depth_sub_.shutdown();
  EXPECT_TRUE(wait_for([&] { return keyframes_pub_.getNumSubscribers() == 0; }, 10.0));
}

TEST_F(InferenceTest, ReloadAndDepthEstimates) {
  umvs_test::RosoutCapture log(nh_);
  subscribe();
  // Started without a checkpoint: sets are refused with a clear message until a model is loaded.
  keyframes_pub_.publish(make_set(1));
  EXPECT_TRUE(log.wait_for("no model loaded", 10.0)) << log.all();

  std::string message;
  EXPECT_FALSE(reload(dir_ + "/corrupt.pt", &message));
  EXPECT_NE(message.find("corrupt.pt"), std::string::npos) << message;
  EXPECT_FALSE(reload(dir_ + "/missing.pt", &message));
  EXPECT_NE(message.find("missing.pt"), std::string::npos) << message;
  ASSERT_TRUE(reload(dir_ + "/model.pt", &message)) << message;

  const auto set = make_set(7);
  keyframes_pub_.publish(set);
  ASSERT_TRUE(wait_for([&] { return !estimates_.empty() && !depth_images_.empty(); }, 60.0)) << log.all();
  const auto& e = *estimates_.front();
  EXPECT_EQ(e.keyframe_id, 7u);
  EXPECT_EQ(e.header.stamp, set.header.stamp);
  EXPECT_EQ(e.header.frame_id, "cam");
  EXPECT_EQ(e.world_frame, "world");
  EXPECT_EQ(e.depth.encoding, "32FC1");
  EXPECT_EQ(e.confidence.encoding, "32FC1");
  EXPECT_EQ(e.image.encoding, "rgb8");
  // 128x96 is a multiple of 32: no resize, the depth map is a quarter of it.
  EXPECT_EQ(e.depth.width, kWidth / 4u);
  EXPECT_EQ(e.depth.height, kHeight / 4u);
  EXPECT_EQ(e.camera_info.width, kWidth / 4u);
  EXPECT_NEAR(e.camera_info.K[0], kFocal / 4, 1e-9);
  EXPECT_NEAR(e.pose.position.x, 0.0, 1e-12);
  EXPECT_FLOAT_EQ(e.depth_min, 1.0f);
  EXPECT_FLOAT_EQ(e.depth_max, 3.0f);
  EXPECT_GT(e.inference_seconds, 0.0f);
  const float* d = reinterpret_cast<const float*>(e.depth.data.data());
  const float* c = reinterpret_cast<const float*>(e.confidence.data.data());
  for (size_t i = 0; i < e.depth.width * e.depth.height; ++i) {
    // Soft-argmin over planes in [1, 3] stays inside the range even with random weights.
    ASSERT_TRUE(d[i] >= 1.0f - 1e-4f && d[i] <= 3.0f + 1e-4f) << d[i];
    ASSERT_TRUE(c[i] >= 0.0f && c[i] <= 1.0f + 1e-5f) << c[i];
  }
  EXPECT_EQ(depth_images_.front()->header.stamp, set.header.stamp);

  // A corrupt checkpoint later keeps the model that works.
  EXPECT_FALSE(reload(dir_ + "/corrupt.pt", &message));
  estimates_.clear();
  keyframes_pub_.publish(make_set(8));
  ASSERT_TRUE(wait_for([&] { return !estimates_.empty(); }, 60.0)) << log.all();
  EXPECT_EQ(estimates_.front()->keyframe_id, 8u);
}

TEST_F(InferenceTest, BadSetsAreLoggedAndSkipped) {
  umvs_test::RosoutCapture log(nh_);
  subscribe();
  std::string message;
  ASSERT_TRUE(reload(dir_ + "/model.pt", &message)) << message;
  ros::WallDuration(2.2).sleep();  // errors are throttled to one per 2 s

  auto wrong_encoding = make_set(20);
  wrong_encoding.reference_image.encoding = "32FC1";
  wrong_encoding.reference_image.step = kWidth * 4;
  wrong_encoding.reference_image.data.resize(kWidth * 4 * kHeight);
  keyframes_pub_.publish(wrong_encoding);
  EXPECT_TRUE(log.wait_for("unsupported image encoding '32FC1'", 10.0)) << log.all();

  ros::WallDuration(2.2).sleep();  // errors are throttled to one per 2 s
  auto nan_pose = make_set(21);
  nan_pose.source_poses[1].orientation.w = std::nan("");
  keyframes_pub_.publish(nan_pose);
  EXPECT_TRUE(log.wait_for("pose has non-finite values", 10.0)) << log.all();

  ros::WallDuration(2.2).sleep();
  auto bad_range = make_set(22);
  bad_range.depth_min = 3.0f;
  bad_range.depth_max = 1.0f;
  keyframes_pub_.publish(bad_range);
  EXPECT_TRUE(log.wait_for("impossible depth range", 10.0)) << log.all();

  // One worker handles the sets in order: an estimate of a bad set would arrive before this one.
  keyframes_pub_.publish(make_set(23));
  ASSERT_TRUE(wait_for([&] { return !estimates_.empty(); }, 60.0)) << log.all();
  ASSERT_EQ(estimates_.size(), 1u) << "a bad set produced an estimate: id " << estimates_.front()->keyframe_id;
  EXPECT_EQ(estimates_.front()->keyframe_id, 23u);
}

TEST_F(InferenceTest, NewestSetsWinWhenBusy) {
  subscribe();
  std::string message;
  ASSERT_TRUE(reload(dir_ + "/model.pt", &message)) << message;
  // Six sets at once, ~queue_size 2 (inference.test). How many are dropped depends on how fast
  // the node finishes a map compared with the publishing (a 32x24 map takes 0.02 s), so no count
  // is asserted here: the drop policy itself is tested without timing in test_latest_slot.cpp
  // (LatestSlot.*). What holds whatever the timing: sets are handled in order and the newest wins.
  for (uint32_t id = 100; id < 106; ++id) keyframes_pub_.publish(make_set(id));
  // The newest set is the last one handled (one worker, in order): all estimates are in by then.
  ASSERT_TRUE(wait_for([&] { return !estimates_.empty() && estimates_.back()->keyframe_id == 105; }, 60.0));
  EXPECT_LE(estimates_.size(), 6u);
  for (size_t i = 1; i < estimates_.size(); ++i) EXPECT_LT(estimates_[i - 1]->keyframe_id, estimates_[i]->keyframe_id);
  EXPECT_EQ(estimates_.back()->keyframe_id, 105u);
  // ~stats counts what the node handled (earlier tests' sets too). No sum is asserted: ROS's own
  // subscriber queue may discard sets of this burst before the node sees them.
  ros::ServiceClient stats = nh_.serviceClient<std_srvs::Trigger>("/inference/stats");
  std_srvs::Trigger call;
  ASSERT_TRUE(stats.call(call));
  long processed = -1, dropped = -1, failed = -1;
  double p50 = -1, p90 = -1;
  ASSERT_EQ(std::sscanf(call.response.message.c_str(),
                        "%ld keyframe sets processed, %ld dropped (stale), %ld failed; image to depth map p50 %lf s, "
                        "p90 %lf s",
                        &processed, &dropped, &failed, &p50, &p90),
            5)
      << call.response.message;
  EXPECT_GE(processed, static_cast<long>(estimates_.size()));
  EXPECT_GE(dropped, 0L);
  EXPECT_GE(failed, 0L);
  EXPECT_GT(p50, 0.0);
  EXPECT_GE(p90, p50);
}

TEST_F(InferenceTest, RefinedPosesAreSentWithTheirEstimates) {
  // inference.test's second node refines the keyframes' poses online. Sources that are the
  // reference's own image from its own pose agree as posed: no turn, so the estimate carries the
  // pose as given (through the refinement's camera and back). A set without source ids is served
  // with its poses as given, and a warning says why.
  umvs_test::RosoutCapture log(nh_);
  std::vector<unsup_mvs::DepthEstimateConstPtr> got;
  ros::Subscriber sub;
  ros::Publisher pub = connect("inference_refining", "refining", &sub, &got);
  ASSERT_FALSE(HasFailure());

  auto set = make_set(40);
  set.reference_pose = umvs_test::make_pose({0.2, -0.1, 0.3}, 5.0);
  for (size_t s = 0; s < set.source_images.size(); ++s) {
    set.source_images[s] = set.reference_image;
    set.source_poses[s] = set.reference_pose;
  }
  pub.publish(set);
  ASSERT_TRUE(wait_for([&] { return !got.empty(); }, 60.0)) << log.all();
  const geometry_msgs::Pose& sent = got.front()->pose;
  const geometry_msgs::Pose& given = set.reference_pose;
  EXPECT_NEAR(sent.position.x, given.position.x, 1e-9);
  EXPECT_NEAR(sent.position.y, given.position.y, 1e-9);
  EXPECT_NEAR(sent.position.z, given.position.z, 1e-9);
  const double dot = sent.orientation.w * given.orientation.w + sent.orientation.x * given.orientation.x +
                     sent.orientation.y * given.orientation.y + sent.orientation.z * given.orientation.z;
  EXPECT_NEAR(std::abs(dot), 1.0, 1e-9) << "the reference was turned";

  auto without_ids = set;
  without_ids.reference_id = 50;
  without_ids.source_ids.clear();
  pub.publish(without_ids);
  EXPECT_TRUE(log.wait_for("its poses are not refined", 30.0)) << log.all();
  ASSERT_TRUE(wait_for([&] { return got.size() == 2; }, 60.0)) << log.all();
  EXPECT_EQ(got.back()->keyframe_id, 50u);
}

TEST_F(InferenceTest, FinePassMakesHalfResolutionMaps) {
  // inference.test's third node runs a fine pass at half the input's resolution (~fine_planes,
  // ~fine_resolution): its maps and their intrinsics are half of the 128x96 input, its depth inside
  // the set's range.
  umvs_test::RosoutCapture log(nh_);
  std::vector<unsup_mvs::DepthEstimateConstPtr> got;
  ros::Subscriber sub;
  ros::Publisher pub = connect("inference_fine", "fine", &sub, &got);
  ASSERT_FALSE(HasFailure());

  pub.publish(make_set(60));
  ASSERT_TRUE(wait_for([&] { return !got.empty(); }, 60.0)) << log.all();
  const auto& e = *got.front();
  EXPECT_EQ(e.keyframe_id, 60u);
  EXPECT_EQ(e.depth.width, kWidth / 2u);
  EXPECT_EQ(e.depth.height, kHeight / 2u);
  EXPECT_EQ(e.confidence.width, kWidth / 2u);
  EXPECT_EQ(e.image.width, kWidth / 2u);
  EXPECT_EQ(e.camera_info.width, kWidth / 2u);
  EXPECT_NEAR(e.camera_info.K[0], kFocal / 2, 1e-9);
  const float* d = reinterpret_cast<const float*>(e.depth.data.data());
  for (size_t i = 0; i < e.depth.width * e.depth.height; ++i) {
    ASSERT_TRUE(d[i] >= 1.0f - 1e-4f && d[i] <= 3.0f + 1e-4f) << d[i];
  }
}

}  // namespace
