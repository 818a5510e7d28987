// End-to-end rostest: a synthetic room (`umvs synth`) logged as a bag (`umvs bag`) is replayed
// (restamped to now) through keyframe_selector -> inference -> fusion as started by
// launch/pipeline.launch; then save_cloud, and the saved PLY is compared with the scene's ground
// truth depth maps.
//
// The model: MVSNet_pytorch's published weights from ../shared/data when present, otherwise the
// shipped default model (models/unsup_mvsnet.pt); either way the cloud must lie on the true surfaces.
#include <ros/callback_queue.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_msgs/TFMessage.h>
#include <torch/torch.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>

#include "rostest_util.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/SaveCloud.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/ply.h"

namespace fs = std::filesystem;

namespace {

const std::string g_source_dir = UMVS_SOURCE_DIR;  // the package source folder

using umvs_test::wait_for;

int run(const std::string& cmd) {
  std::cout << "[pipeline test] " << cmd << std::endl;
  return std::system(cmd.c_str());
}

TEST(Pipeline, SyntheticBagToFusedCloud) {
  ros::NodeHandle nh;
  const std::string dir = umvs_test::temp_dir("pipeline");
  const std::string umvs = umvs_test::bin_dir() + "/umvs";
  ASSERT_EQ(run(umvs + " synth --scene room --seed 1 --views 16 --width 320 --height 256 --gt-samples 0 --textures none --out " + dir +
                "/scene > " + dir + "/synth.log 2>&1"), 0);
  ASSERT_EQ(run(umvs + " bag --data " + dir + "/scene --out " + dir + "/log.bag --rate 1 --start 1000"), 0);

  // The model.
  std::string model = g_source_dir + "/../shared/data/mvsnet_parity/mvsnet_pytorch_d192.pt";
  if (const char* env = std::getenv("UMVS_SHARED_DATA")) model = std::string(env) + "/mvsnet_parity/mvsnet_pytorch_d192.pt";
  const bool published = fs::exists(model);
  if (!published) model = g_source_dir + "/models/unsup_mvsnet.pt";
  ASSERT_TRUE(fs::exists(model)) << model;
  auto reload = nh.serviceClient<unsup_mvs::ReloadModel>("/unsup_mvs/inference/reload_model");
  ASSERT_TRUE(reload.waitForExistence(ros::Duration(60.0))) << "pipeline did not come up";
  unsup_mvs::ReloadModel srv;
  srv.request.checkpoint = model;
  ASSERT_TRUE(reload.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;

  // Watch the pipeline.
  std::vector<unsup_mvs::KeyframeSetConstPtr> sets;
  std::vector<std::pair<unsup_mvs::DepthEstimateConstPtr, double>> estimates;  // + latency (s)
  ros::Time cloud_stamp;
  auto cloud_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "/unsup_mvs/cloud", 1, [&](const sensor_msgs::PointCloud2ConstPtr& m) { cloud_stamp = m->header.stamp; });
  auto set_sub = nh.subscribe<unsup_mvs::KeyframeSet>("/unsup_mvs/keyframes", 20,
                                                      [&](const unsup_mvs::KeyframeSetConstPtr& m) { sets.push_back(m); });
  auto est_sub = nh.subscribe<unsup_mvs::DepthEstimate>("/unsup_mvs/depth_estimate", 20, [&](const unsup_mvs::DepthEstimateConstPtr& m) {
    estimates.emplace_back(m, (ros::Time::now() - m->header.stamp).toSec());
  });
  // Online latency: wall-clock arrival of each keyframe set and of the points the fusion node
  // publishes for it (same stamp), taken on a spinner thread of their own so that the replay's
  // sleeps below do not delay them.
  ros::CallbackQueue timing_queue;
  ros::NodeHandle timing_nh;
  timing_nh.setCallbackQueue(&timing_queue);
  std::mutex timing_mutex;
  std::map<ros::Time, double> set_arrival, points_arrival;
  auto set_timing = timing_nh.subscribe<unsup_mvs::KeyframeSet>("/unsup_mvs/keyframes", 20, [&](const unsup_mvs::KeyframeSetConstPtr& m) {
    std::lock_guard<std::mutex> lock(timing_mutex);
    set_arrival.emplace(m->header.stamp, ros::WallTime::now().toSec());
  });
  auto points_timing = timing_nh.subscribe<sensor_msgs::PointCloud2>("/unsup_mvs/cloud_increment", 20, [&](const sensor_msgs::PointCloud2ConstPtr& m) {
    std::lock_guard<std::mutex> lock(timing_mutex);
    points_arrival.emplace(m->header.stamp, ros::WallTime::now().toSec());
  });
  ros::AsyncSpinner timing_spinner(1, &timing_queue);
  timing_spinner.start();
  auto image_pub = nh.advertise<sensor_msgs::Image>("/camera/image_rect_color", 5);
  auto info_pub = nh.advertise<sensor_msgs::CameraInfo>("/camera/camera_info", 5);
  auto tf_pub = nh.advertise<tf2_msgs::TFMessage>("/tf", 50);
  ASSERT_TRUE(wait_for([&] { return image_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
                                    tf_pub.getNumSubscribers() > 0 && set_sub.getNumPublishers() > 0 &&
                                    est_sub.getNumPublishers() > 0; }, 30.0));

  // Replay the bag at its rate, each frame restamped to now (so latencies are wall-clock figures).
  rosbag::Bag bag(dir + "/log.bag");
  rosbag::View view(bag);
  std::map<ros::Time, ros::Time> restamp;
  ros::Time previous_bag_time;
  int frames = 0;
  for (const rosbag::MessageInstance& m : view) {
    const ros::Time t = m.getTime();
    if (!restamp.count(t)) {
      if (!previous_bag_time.isZero()) ros::WallDuration((t - previous_bag_time).toSec()).sleep();
      previous_bag_time = t;
      restamp[t] = ros::Time::now();
      ++frames;
    }
    const ros::Time now = restamp[t];
    if (auto tf = m.instantiate<tf2_msgs::TFMessage>()) {
      tf2_msgs::TFMessage out = *tf;
      for (auto& x : out.transforms) x.header.stamp = now;
      tf_pub.publish(out);
      ros::WallDuration(0.02).sleep();
    } else if (auto info = m.instantiate<sensor_msgs::CameraInfo>()) {
      sensor_msgs::CameraInfo out = *info;
      out.header.stamp = now;
      info_pub.publish(out);
    } else if (auto image = m.instantiate<sensor_msgs::Image>()) {
      sensor_msgs::Image out = *image;
      out.header.stamp = now;
      image_pub.publish(out);
    }
    ros::spinOnce();
  }
  bag.close();
  ASSERT_EQ(frames, 16);
  ASSERT_TRUE(wait_for([&] { return sets.size() >= 3; }, 10.0)) << sets.size() << " keyframe sets";
  // Wait until the newest keyframe set has its depth estimate.
  ASSERT_TRUE(wait_for([&] { return !estimates.empty() && estimates.back().first->keyframe_id == sets.back()->reference_id; }, 60.0));
  // The fusion node has fused the last estimate when its map carries that estimate's stamp.
  const ros::Time last_estimate = estimates.back().first->header.stamp;
  ASSERT_TRUE(wait_for([&] { return cloud_stamp == last_estimate; }, 30.0)) << "the map never included the last estimate";

  for (const auto& [e, latency] : estimates) {
    EXPECT_EQ(e->header.frame_id, "camera_optical_frame");
    EXPECT_EQ(e->world_frame, "world");
    const auto it = std::find_if(sets.begin(), sets.end(), [&](const auto& s) { return s->reference_id == e->keyframe_id; });
    ASSERT_NE(it, sets.end());
    EXPECT_EQ(e->header.stamp, (*it)->reference_image.header.stamp);
    EXPECT_EQ(e->pose.position.x, (*it)->reference_pose.position.x);  // no pose refinement: the pose as given
    EXPECT_EQ(e->pose.orientation.w, (*it)->reference_pose.orientation.w);
  }

  auto save = nh.serviceClient<unsup_mvs::SaveCloud>("/unsup_mvs/fusion/save_cloud");
  unsup_mvs::SaveCloud save_srv;
  save_srv.request.path = "pipeline_cloud.ply";  // relative: inside fusion's ~save_dir
  ASSERT_TRUE(save.call(save_srv));
  double latency_sum = 0, network_sum = 0;
  for (const auto& [e, latency] : estimates) {
    latency_sum += latency;
    network_sum += e->inference_seconds;
  }
  std::printf("[pipeline test] %d frames -> %zu keyframe sets -> %zu depth maps -> %lu points; latency per keyframe "
              "(image to depth estimate) %.2f s, network %.2f s; model %s\n",
              frames, sets.size(), estimates.size(), static_cast<unsigned long>(save_srv.response.num_points),
              latency_sum / estimates.size(), network_sum / estimates.size(), published ? "MVSNet_pytorch" : "the default model");

  {
    std::lock_guard<std::mutex> lock(timing_mutex);
    std::vector<double> latency;
    for (const auto& [stamp, t_points] : points_arrival) {
      if (set_arrival.count(stamp)) latency.push_back(t_points - set_arrival.at(stamp));
    }
    std::sort(latency.begin(), latency.end());
    const auto pct = [&](double p) { return latency.empty() ? 0.0 : latency[static_cast<size_t>(p * (latency.size() - 1) + 0.5)]; };
    std::printf("[pipeline test] keyframe set -> fused points published: %zu sets with points; latency p50 %.3f s, "
                "p90 %.3f s, max %.3f s\n", latency.size(), pct(0.5), pct(0.9), pct(1.0));
  }
  timing_spinner.stop();

  ASSERT_TRUE(save_srv.response.success) << save_srv.response.message;
  std::string clouds_dir;
  ASSERT_TRUE(nh.getParam("/unsup_mvs/fusion/save_dir", clouds_dir));
  const umvs::PointCloud cloud = umvs::read_ply(clouds_dir + "/pipeline_cloud.ply");
  ASSERT_EQ(cloud.size(), save_srv.response.num_points);
  ASSERT_GT(cloud.size(), 1000u);

  // Distance of each point to the true surface, as the relative depth error in the ground-truth
  // view that explains the point best.
  umvs::MvsFolder scene(dir + "/scene");
  std::vector<umvs::Camera> cams;
  std::vector<torch::Tensor> gts;
  for (const auto& p : scene.pairs()) {
    cams.push_back(scene.load_view(p.ref).cam.camera);
    gts.push_back(umvs::read_pfm(scene.depth_gt_path(p.ref)));
  }
  std::vector<double> errors;
  for (const auto& pf : cloud.points) {
    const Eigen::Vector3d p = pf.cast<double>();
    double best = 1e9;
    for (size_t v = 0; v < cams.size(); ++v) {
      Eigen::Vector2d uv;
      double z = 0;
      if (!cams[v].project(p, &uv, &z) || !cams[v].in_image(uv)) continue;
      const float gt = gts[v][std::lround(uv.y())][std::lround(uv.x())].item<float>();
      if (gt > 0) best = std::min(best, std::abs(z - gt) / gt);
    }
    errors.push_back(best);
  }
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2];
  const double within5 = std::lower_bound(errors.begin(), errors.end(), 0.05) - errors.begin();
  std::printf("[pipeline test] points vs ground truth: median relative depth error %.4f, %.1f%% within 5%%\n", median,
              100.0 * within5 / errors.size());
  EXPECT_LT(median, 0.03);
  EXPECT_GT(within5 / errors.size(), 0.75);
}

}  // namespace
