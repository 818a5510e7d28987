// rostest for live tuning (dynamic_reconfigure, cfg/*.cfg): each node's server starts with the
// values the node was launched with; a valid change is reported and takes effect on the next
// input (fusion: fewer points from the same depth maps; inference: a smaller depth map); an
// invalid one (allowed by the cfg ranges, refused by the start-up validation) is logged naming the
// parameter, the reported config and the parameter server keep the old values, and the node keeps
// working with them.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Config.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <sensor_msgs/PointCloud2.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "reconfigure_client.h"
#include "rostest_util.h"
#include "test_messages.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/ResetFusion.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/ros/live_settings.h"
#include "unsup_mvs/ros/params.h"
#include "unsup_mvs/ros/reconfigure.h"

namespace {

using umvs_test::wait_for;

using umvs_test::reconfigure;
using umvs_test::Request;

double double_of(const dynamic_reconfigure::Config& c, const std::string& name) {
  for (const auto& p : c.doubles) {
    if (p.name == name) return p.value;
  }
  ADD_FAILURE() << "no double parameter " << name;
  return std::numeric_limits<double>::quiet_NaN();
}

int int_of(const dynamic_reconfigure::Config& c, const std::string& name) {
  for (const auto& p : c.ints) {
    if (p.name == name) return p.value;
  }
  ADD_FAILURE() << "no int parameter " << name;
  return -1;
}

// --- fusion ----------------------------------------------------------------------------------

constexpr char kFusion[] = "/f/fusion";
constexpr int kDepthWidth = 64, kDepthHeight = 48;
constexpr double kPlaneZ = 3.0;

// Camera at (x, 0, 0) looking along +z at the plane z = kPlaneZ, confidence 0.9 everywhere.
unsup_mvs::DepthEstimate make_estimate(uint32_t id, double x) {
  unsup_mvs::DepthEstimate e;
  e.header.stamp = ros::Time::now();
  e.header.frame_id = "cam";
  e.keyframe_id = id;
  e.depth = umvs::float_to_image_msg(torch::full({kDepthHeight, kDepthWidth}, kPlaneZ, torch::kFloat32), e.header);
  e.confidence = umvs::float_to_image_msg(torch::full({kDepthHeight, kDepthWidth}, 0.9f), e.header);
  e.camera_info = umvs_test::make_info(kDepthWidth, kDepthHeight, 50.0, e.header);
  e.world_frame = "world";
  e.pose = umvs_test::make_pose({x, 0, 0});
  e.depth_min = 1;
  e.depth_max = 5;
  return e;
}

class FusionReconfigureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    estimate_pub_ = nh_.advertise<unsup_mvs::DepthEstimate>("/f/depth_estimate", 10);
    cloud_sub_ = nh_.subscribe<sensor_msgs::PointCloud2>("/f/cloud", 5, [this](const sensor_msgs::PointCloud2ConstPtr& m) {
      cloud_ = m;
    });
    reset_ = nh_.serviceClient<unsup_mvs::ResetFusion>(std::string(kFusion) + "/reset");
    ASSERT_TRUE(reset_.waitForExistence(ros::Duration(30.0))) << "fusion did not come up";
    ASSERT_TRUE(wait_for([&] { return estimate_pub_.getNumSubscribers() > 0 && cloud_sub_.getNumPublishers() > 0; }, 10.0));
  }

  // Clears the map, then fuses three depth maps of the plane from x = 0, 0.1, 0.2, each once the
  // map including the previous one is out. Returns the points of the final map.
  size_t fuseThreeViews() {
    unsup_mvs::ResetFusion r;
    EXPECT_TRUE(reset_.call(r));
    for (uint32_t i = 0; i < 3; ++i) {
      const auto e = make_estimate(next_id_++, 0.1 * i);
      estimate_pub_.publish(e);
      if (!wait_for([&] { return cloud_ && cloud_->header.stamp == e.header.stamp; }, 20.0)) {
        ADD_FAILURE() << "no map with depth estimate " << e.keyframe_id;
        return 0;
      }
    }
    return cloud_->width * cloud_->height;
  }

  ros::NodeHandle nh_;
  ros::Publisher estimate_pub_;
  ros::Subscriber cloud_sub_;
  ros::ServiceClient reset_;
  sensor_msgs::PointCloud2ConstPtr cloud_;
  uint32_t next_id_ = 0;
};

TEST_F(FusionReconfigureTest, StartsWithTheLaunchValues) {
  const auto c = reconfigure(kFusion);
  // dynamic_reconfigure.test sets these (the cfg defaults are 0.8 and 3) ...
  EXPECT_DOUBLE_EQ(double_of(c, "min_confidence"), 0.5);
  EXPECT_EQ(int_of(c, "min_agreeing_views"), 2);
  EXPECT_DOUBLE_EQ(double_of(c, "voxel_size"), 0.0);
  // ... and leaves these at FusionConfig's defaults.
  EXPECT_DOUBLE_EQ(double_of(c, "max_reprojection_px"), 1.0);
  EXPECT_DOUBLE_EQ(double_of(c, "max_relative_depth"), 0.01);
}

TEST_F(FusionReconfigureTest, ConfidenceThresholdTakesEffectOnTheNextDepthMap) {
  const size_t before = fuseThreeViews();
  ASSERT_GT(before, 1000u) << "min_agreeing_views 2: the third view confirms the plane";

  // Above the maps' 0.9 confidence: no pixel is an estimate any more.
  auto c = reconfigure(kFusion, Request().set("min_confidence", 0.95));
  EXPECT_DOUBLE_EQ(double_of(c, "min_confidence"), 0.95);
  EXPECT_EQ(fuseThreeViews(), 0u);

  // More agreeing views than two other maps can give: nothing either.
  reconfigure(kFusion, Request().set("min_confidence", 0.5));
  c = reconfigure(kFusion, Request().set("min_agreeing_views", 3));
  EXPECT_EQ(int_of(c, "min_agreeing_views"), 3);
  EXPECT_EQ(fuseThreeViews(), 0u);

  // Back to the launch values: the same points as before.
  c = reconfigure(kFusion, Request().set("min_agreeing_views", 2));
  EXPECT_EQ(int_of(c, "min_agreeing_views"), 2);
  EXPECT_DOUBLE_EQ(double_of(c, "min_confidence"), 0.5);
  EXPECT_EQ(fuseThreeViews(), before);
}

TEST_F(FusionReconfigureTest, InvalidValuesAreRefusedAndTheOldOnesKept) {
  umvs_test::RosoutCapture log(nh_);
  // 0 is inside the cfg range [0, 100] but FusionConfig::validate wants > 0.
  auto c = reconfigure(kFusion, Request().set("max_reprojection_px", 0.0));
  EXPECT_DOUBLE_EQ(double_of(c, "max_reprojection_px"), 1.0) << "the reported config keeps the old value";
  EXPECT_TRUE(log.wait_for("max_reprojection_px must be > 0", 10.0)) << log.all();
  double on_server = 0;
  ASSERT_TRUE(nh_.getParam(std::string(kFusion) + "/max_reprojection_px", on_server));
  EXPECT_DOUBLE_EQ(on_server, 1.0);

  // A request is taken or refused as a whole: the valid part of a refused one is not applied.
  c = reconfigure(kFusion, Request().set("min_agreeing_views", 4).set("max_relative_depth", 0.0));
  EXPECT_EQ(int_of(c, "min_agreeing_views"), 2);
  EXPECT_DOUBLE_EQ(double_of(c, "max_relative_depth"), 0.01);
  EXPECT_TRUE(log.wait_for("max_relative_depth must be > 0", 10.0)) << log.all();
  c = reconfigure(kFusion);
  EXPECT_EQ(int_of(c, "min_agreeing_views"), 2);
  EXPECT_DOUBLE_EQ(double_of(c, "max_reprojection_px"), 1.0);

  // Still fusing, with the old thresholds.
  EXPECT_GT(fuseThreeViews(), 1000u);
}

// --- keyframe_selector -----------------------------------------------------------------------

constexpr char kSelector[] = "/k/keyframe_selector";

TEST(KeyframeSelectorReconfigureTest, StartsWithTheLaunchValuesAndChecksRequests) {
  ros::NodeHandle nh;
  umvs_test::RosoutCapture log(nh);
  auto c = reconfigure(kSelector);
  EXPECT_DOUBLE_EQ(double_of(c, "min_translation"), 0.2);
  EXPECT_DOUBLE_EQ(double_of(c, "min_rotation_deg"), 10.0);
  EXPECT_EQ(int_of(c, "buffer_size"), 20);
  EXPECT_EQ(int_of(c, "num_sources"), 2);
  EXPECT_DOUBLE_EQ(double_of(c, "max_wait_s"), 2.0);
  EXPECT_DOUBLE_EQ(double_of(c, "depth_min"), 1.0);
  EXPECT_DOUBLE_EQ(double_of(c, "depth_max"), 4.0);

  // Inconsistent with the other values: refused, the old ones kept.
  c = reconfigure(kSelector, Request().set("depth_min", 5.0));
  EXPECT_DOUBLE_EQ(double_of(c, "depth_min"), 1.0);
  EXPECT_TRUE(log.wait_for("need 0 < depth_min < depth_max", 10.0)) << log.all();
  c = reconfigure(kSelector, Request().set("buffer_size", 2));
  EXPECT_EQ(int_of(c, "buffer_size"), 20);
  EXPECT_TRUE(log.wait_for("buffer_size must be at least num_sources + lookahead + 1", 10.0)) << log.all();

  c = reconfigure(kSelector, Request().set("num_sources", 3).set("depth_max", 8.0).set("buffer_size", 5));
  EXPECT_EQ(int_of(c, "num_sources"), 3);
  EXPECT_DOUBLE_EQ(double_of(c, "depth_max"), 8.0);
  EXPECT_EQ(int_of(c, "buffer_size"), 5);
  double on_server = 0;
  ASSERT_TRUE(nh.getParam(std::string(kSelector) + "/depth_max", on_server));
  EXPECT_DOUBLE_EQ(on_server, 8.0);
}

// --- inference -------------------------------------------------------------------------------

constexpr char kInference[] = "/i/inference";
constexpr int kWidth = 128, kHeight = 96;

unsup_mvs::KeyframeSet make_set(uint32_t id) { return umvs_test::keyframe_set(id, {kWidth, kHeight, 100.0, "cam"}); }

TEST(InferenceReconfigureTest, ResolutionPlanesAndPoseRefinementTakeEffectAndBadValuesAreRefused) {
  ros::NodeHandle nh;
  umvs_test::RosoutCapture log(nh);
  auto c = reconfigure(kInference);
  EXPECT_EQ(int_of(c, "max_width"), 128);
  EXPECT_EQ(int_of(c, "max_height"), 96);
  EXPECT_EQ(int_of(c, "num_depth"), 16);

  const std::string dir = umvs_test::temp_dir("dynamic_reconfigure");
  torch::manual_seed(0);
  umvs::MvsNet net(umvs::MvsNetConfig{});
  umvs::save_checkpoint(dir + "/model.pt", net);
  ros::ServiceClient reload = nh.serviceClient<unsup_mvs::ReloadModel>(std::string(kInference) + "/reload_model");
  ASSERT_TRUE(reload.waitForExistence(ros::Duration(30.0)));
  unsup_mvs::ReloadModel srv;
  srv.request.checkpoint = dir + "/model.pt";
  ASSERT_TRUE(reload.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;

  std::vector<unsup_mvs::DepthEstimateConstPtr> estimates;
  ros::Publisher keyframes = nh.advertise<unsup_mvs::KeyframeSet>("/i/keyframes", 2);
  ros::Subscriber sub = nh.subscribe<unsup_mvs::DepthEstimate>(
      "/i/depth_estimate", 5, [&](const unsup_mvs::DepthEstimateConstPtr& m) { estimates.push_back(m); });
  ASSERT_TRUE(wait_for([&] { return keyframes.getNumSubscribers() > 0; }, 10.0)) << "inference subscribes lazily";
  auto estimate = [&](uint32_t id) -> unsup_mvs::DepthEstimateConstPtr {
    keyframes.publish(make_set(id));
    if (!wait_for([&] { return !estimates.empty() && estimates.back()->keyframe_id == id; }, 60.0)) return nullptr;
    return estimates.back();
  };
  auto e = estimate(1);
  ASSERT_TRUE(e) << log.all();
  EXPECT_EQ(e->depth.width, kWidth / 4u);  // 128 x 96: no resize, a quarter-size depth map
  EXPECT_EQ(e->depth.height, kHeight / 4u);

  // Not a multiple of 8; more than ~max_planes (256); too small for the network: all inside the
  // cfg ranges, all refused by InferenceNodeConfig::validate.
  c = reconfigure(kInference, Request().set("num_depth", 12));
  EXPECT_EQ(int_of(c, "num_depth"), 16);
  EXPECT_TRUE(log.wait_for("num_depth must be 0", 10.0)) << log.all();
  c = reconfigure(kInference, Request().set("num_depth", 512));
  EXPECT_EQ(int_of(c, "num_depth"), 16);
  EXPECT_TRUE(log.wait_for("num_depth 512 is more than max_planes 256", 10.0)) << log.all();
  c = reconfigure(kInference, Request().set("max_width", 16));
  EXPECT_EQ(int_of(c, "max_width"), 128);
  EXPECT_TRUE(log.wait_for("max_width must be 0 (no limit) or at least 32, got 16", 10.0)) << log.all();

  // 128 x 96 scaled by 0.5 to fit 64 x 64 is 64 x 48, cropped to 64 x 32: a 16 x 8 depth map.
  c = reconfigure(kInference, Request().set("max_width", 64).set("max_height", 64).set("num_depth", 8));
  EXPECT_EQ(int_of(c, "max_width"), 64);
  EXPECT_EQ(int_of(c, "num_depth"), 8);
  e = estimate(2);
  ASSERT_TRUE(e) << log.all();
  EXPECT_EQ(e->depth.width, 16u);
  EXPECT_EQ(e->depth.height, 8u);
  EXPECT_NEAR(e->camera_info.K[0], 100.0 * 0.5 / 4, 1e-9);

  // The online pose refinement turns on and off live; /diagnostics says what it knows.
  std::string refinement, planes;
  ros::Subscriber diagnostics = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
        for (const auto& status : m->status) {
          for (const auto& value : status.values) {
            if (value.key == "pose_refinement") refinement = value.value;
            if (value.key == "depth_planes") planes = value.value;
          }
        }
      });
  ASSERT_TRUE(wait_for([&] { return diagnostics.getNumPublishers() > 0; }, 10.0));
  EXPECT_DOUBLE_EQ(double_of(c, "pose_refinement_deg"), 0.0);
  c = reconfigure(kInference, Request().set("pose_refinement_deg", 1.0));
  EXPECT_DOUBLE_EQ(double_of(c, "pose_refinement_deg"), 1.0);
  ASSERT_TRUE(estimate(3)) << log.all();
  EXPECT_TRUE(wait_for([&] { return refinement == "2 pairs over 3 keyframes"; }, 10.0)) << refinement;
  c = reconfigure(kInference, Request().set("pose_refinement_deg", 0.0));
  EXPECT_DOUBLE_EQ(double_of(c, "pose_refinement_deg"), 0.0);
  ASSERT_TRUE(estimate(4)) << log.all();
  EXPECT_TRUE(wait_for([&] { return refinement == "off"; }, 10.0)) << refinement;
  EXPECT_EQ(planes, "8");

  // num_depth 0: the planes follow the network input as in `umvs infer` (128 at 640 wide, scaled
  // with the width, at least 16), not the checkpoint's count (MvsNetConfig's default).
  ASSERT_NE(umvs::MvsNetConfig{}.num_depth, 24);
  c = reconfigure(kInference, Request().set("num_depth", 0));
  EXPECT_EQ(int_of(c, "num_depth"), 0);
  ASSERT_TRUE(estimate(5)) << log.all();
  EXPECT_TRUE(wait_for([&] { return planes == "16"; }, 10.0)) << planes;  // 64 wide
  c = reconfigure(kInference, Request().set("max_width", 128).set("max_height", 96));
  ASSERT_TRUE(estimate(6)) << log.all();
  EXPECT_TRUE(wait_for([&] { return planes == "24"; }, 10.0)) << planes;  // 128 wide
}

}  // namespace
