// rostest: with online pose refinement the depth map, the fused cloud and the map are in one frame.
// A rendered room's view is sent as a keyframe set's reference, its pose turned by 0.8 degrees as a
// drifting odometry would give it, with the robot's tf (world -> cam) at that pose. The inference
// node turns it back; its depth camera must then name "cam_refined", tf must place that frame at the
// pose the estimate carries to fusion, and every point fusion makes from the map must sit on its
// pixel of the depth image as depth_image_proc would place it through tf.
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <cmath>

#include "rostest_util.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace {

using umvs_test::wait_for;

// The angle between two orientations, degrees.
double angle_deg(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  return umvs::rotation_angle(a.topLeftCorner<3, 3>(), b.topLeftCorner<3, 3>()) * 180.0 / M_PI;
}

TEST(RefinedFrame, DepthCloudAndTfAgreeInTheRefinedCamerasFrame) {
  ros::NodeHandle nh;
  umvs_test::RosoutCapture log(nh);
  umvs::SynthConfig cfg;
  cfg.seed = 81;
  cfg.num_views = 6;
  cfg.lighting_change = false;
  cfg.supersample = 1;
  cfg.gt_cloud_samples = 0;
  const umvs::SynthScene scene = umvs::render_synthetic_scene(cfg);
  const int ref = 2;
  const umvs::Camera given = scene.views[ref].camera.turned(Eigen::Vector3d(0.6, -0.5, 0.3) * M_PI / 180.0);

  unsup_mvs::KeyframeSet set;
  set.header.stamp = ros::Time::now();
  set.header.frame_id = "world";
  set.reference_id = ref;
  std_msgs::Header header;
  header.frame_id = "cam";
  header.stamp = set.header.stamp - ros::Duration(0.25);  // the image's own stamp, apart from the set's
  set.reference_image = umvs::rgb8_to_image_msg(scene.views[ref].image, header);
  set.reference_info = umvs::camera_info_from_camera(given, header);
  set.reference_pose = umvs::matrix_to_pose(given.T_cam_world.inverse());
  for (int s = 0; s < 2; ++s) {
    const int id = scene.pairs[ref][s].first;
    std_msgs::Header h = header;
    h.stamp -= ros::Duration(1.0 + s);
    set.source_ids.push_back(id);
    set.source_images.push_back(umvs::rgb8_to_image_msg(scene.views[id].image, h));
    set.source_infos.push_back(umvs::camera_info_from_camera(scene.views[id].camera, h));
    set.source_poses.push_back(umvs::matrix_to_pose(scene.views[id].camera.T_cam_world.inverse()));
  }
  set.depth_min = static_cast<float>(scene.depth_min);
  set.depth_max = static_cast<float>(scene.depth_max);

  // The robot's tf: the camera where its odometry says (static here: latched, so it cannot be missed).
  tf2_ros::StaticTransformBroadcaster robot_tf;
  geometry_msgs::TransformStamped camera;
  camera.header = header;
  camera.header.frame_id = "world";
  camera.child_frame_id = "cam";
  camera.transform = umvs::matrix_to_transform(given.T_cam_world.inverse());

  unsup_mvs::DepthEstimateConstPtr estimate;
  sensor_msgs::ImageConstPtr depth;
  sensor_msgs::CameraInfoConstPtr depth_info;
  sensor_msgs::PointCloud2ConstPtr points;
  auto est_sub = nh.subscribe<unsup_mvs::DepthEstimate>("/depth_estimate", 2,
                                                        [&](const unsup_mvs::DepthEstimateConstPtr& m) { estimate = m; });
  auto depth_sub = nh.subscribe<sensor_msgs::Image>("/depth/image", 2, [&](const sensor_msgs::ImageConstPtr& m) { depth = m; });
  auto info_sub = nh.subscribe<sensor_msgs::CameraInfo>("/depth/camera_info", 2,
                                                        [&](const sensor_msgs::CameraInfoConstPtr& m) { depth_info = m; });
  auto cloud_sub = nh.subscribe<sensor_msgs::PointCloud2>("/cloud_increment", 2,
                                                          [&](const sensor_msgs::PointCloud2ConstPtr& m) { points = m; });
  tf2_ros::Buffer tf_buffer;
  tf2_ros::TransformListener tf_listener(tf_buffer);
  ros::Publisher pub = nh.advertise<unsup_mvs::KeyframeSet>("/keyframes", 1);
  ASSERT_TRUE(wait_for([&] { return pub.getNumSubscribers() > 0 && cloud_sub.getNumPublishers() > 0; }, 60.0))
      << "inference and fusion did not come up";
  robot_tf.sendTransform(camera);
  pub.publish(set);
  ASSERT_TRUE(wait_for([&] { return estimate && depth && depth_info && points; }, 120.0)) << log.all();

  // The estimate is in the refined camera: turned back, and named so.
  EXPECT_EQ(estimate->header.frame_id, "cam_refined");
  EXPECT_EQ(depth->header.frame_id, "cam_refined");
  EXPECT_EQ(depth_info->header.frame_id, "cam_refined");
  EXPECT_EQ(depth->header.stamp, set.reference_image.header.stamp);
  const Eigen::Matrix4d sent = umvs::pose_to_matrix(estimate->pose);
  const Eigen::Matrix4d odometry = given.T_cam_world.inverse();
  const double turned = angle_deg(sent, odometry);
  RecordProperty("reference_turned_deg", std::to_string(turned));
  EXPECT_GT(turned, 0.2) << "the refinement did not turn the reference (off by 0.84 degrees)";
  const Eigen::Matrix4d truth = scene.views[ref].camera.T_cam_world.inverse();
  EXPECT_LT(angle_deg(sent, truth), angle_deg(odometry, truth)) << "turned, but not back towards the rendered pose";

  // tf places the refined frame at the estimate's pose; the robot's own frame is left alone.
  ASSERT_TRUE(tf_buffer.canTransform("world", "cam_refined", depth->header.stamp, ros::Duration(10.0)));
  const Eigen::Matrix4d refined_tf =
      umvs::transform_to_matrix(tf_buffer.lookupTransform("world", "cam_refined", depth->header.stamp).transform);
  EXPECT_LT((refined_tf - sent).cwiseAbs().maxCoeff(), 1e-6) << refined_tf << "\n" << sent;
  ASSERT_TRUE(tf_buffer.canTransform("world", "cam", depth->header.stamp, ros::Duration(10.0)));
  const Eigen::Matrix4d robot =
      umvs::transform_to_matrix(tf_buffer.lookupTransform("world", "cam", depth->header.stamp).transform);
  EXPECT_LT((robot - odometry).cwiseAbs().maxCoeff(), 1e-6);

  // Every fused point lies on its pixel of the depth image, at its depth, placed through tf.
  ASSERT_EQ(depth->encoding, "32FC1");
  const float* d = reinterpret_cast<const float*>(depth->data.data());
  const Eigen::Matrix4d world_to_cam = refined_tf.inverse();
  const double fx = depth_info->K[0], fy = depth_info->K[4], cx = depth_info->K[2], cy = depth_info->K[5];
  size_t checked = 0;
  double worst_px = 0, worst_rel = 0;
  for (sensor_msgs::PointCloud2ConstIterator<float> p(*points, "x"); p != p.end(); ++p) {
    const Eigen::Vector4d c = world_to_cam * Eigen::Vector4d(p[0], p[1], p[2], 1.0);
    const double u = fx * c.x() / c.z() + cx, v = fy * c.y() / c.z() + cy;
    const long col = std::lround(u), row = std::lround(v);
    ASSERT_TRUE(col >= 0 && row >= 0 && col < static_cast<long>(depth->width) && row < static_cast<long>(depth->height))
        << "a fused point falls outside the depth image at (" << u << ", " << v << ")";
    worst_px = std::max({worst_px, std::abs(u - col), std::abs(v - row)});
    const float z = d[row * depth->width + col];
    ASSERT_TRUE(std::isfinite(z)) << "a fused point on pixel (" << col << ", " << row << ") the depth image calls unknown";
    worst_rel = std::max(worst_rel, std::abs(c.z() - z) / z);
    ++checked;
  }
  RecordProperty("fused_points_checked", std::to_string(checked));
  EXPECT_GT(checked, depth->width * depth->height / 10) << "too few fused points to tell";
  EXPECT_LT(worst_px, 0.01) << "fused points are off their pixels through tf";
  EXPECT_LT(worst_rel, 1e-4);
}

}  // namespace
