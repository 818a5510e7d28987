// Messages the rostests send to the nodes: keyframe sets of test images for inference, and depth
// estimates of a plane for fusion.
#pragma once

#include <torch/torch.h>

#include <array>
#include <cstdint>
#include <string>

#include "rostest_util.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/io/ros/ros_conversions.h"

namespace umvs_test {

// A pinhole camera with its principal point at the image centre (make_info).
struct TestCamera {
  int width;
  int height;
  double focal;
  std::string frame;  // the images' frame_id, which the tests use to tell their own messages apart
};

// A keyframe set for inference: the reference view at the origin, two source views 0.1 m and
// 0.2 m along x (make_image shifted by 3 and 6 pixels), depth range 1-3 m.
inline unsup_mvs::KeyframeSet keyframe_set(uint32_t id, const TestCamera& camera) {
  unsup_mvs::KeyframeSet s;
  s.header.stamp = ros::Time::now();
  s.header.frame_id = "world";
  s.reference_id = id;
  std_msgs::Header h;
  h.stamp = s.header.stamp;
  h.frame_id = camera.frame;
  s.reference_image = make_image(camera.width, camera.height, h, 0);
  s.reference_info = make_info(camera.width, camera.height, camera.focal, h);
  s.reference_pose = make_pose({0, 0, 0});
  for (int j = 1; j <= 2; ++j) {
    s.source_ids.push_back(id + j);
    s.source_images.push_back(make_image(camera.width, camera.height, h, 3 * j));
    s.source_infos.push_back(make_info(camera.width, camera.height, camera.focal, h));
    s.source_poses.push_back(make_pose({0.1 * j, 0, 0}));
  }
  s.depth_min = 1.0f;
  s.depth_max = 3.0f;
  return s;
}

// The plane plane_estimate sees, and the size and focal length of its depth maps.
constexpr double kPlaneZ = 3.0;
constexpr int kPlaneWidth = 64, kPlaneHeight = 48;
constexpr double kPlaneFocal = 50.0;

// A depth estimate from a camera at (x, 0, 0) looking along +z at the plane z = kPlaneZ: depth
// kPlaneZ and confidence 0.9 everywhere, one colour, depth range 1-5 m, in world frame "world".
inline unsup_mvs::DepthEstimate plane_estimate(uint32_t id, double x, const std::string& camera_frame,
                                               const std::array<uint8_t, 3>& rgb = {128, 128, 128}) {
  unsup_mvs::DepthEstimate e;
  e.header.stamp = ros::Time::now();
  e.header.frame_id = camera_frame;
  e.keyframe_id = id;
  e.depth = umvs::float_to_image_msg(torch::full({kPlaneHeight, kPlaneWidth}, kPlaneZ, torch::kFloat32), e.header);
  e.confidence = umvs::float_to_image_msg(torch::full({kPlaneHeight, kPlaneWidth}, 0.9f), e.header);
  auto color = torch::empty({kPlaneHeight, kPlaneWidth, 3}, torch::kUInt8);
  for (int c = 0; c < 3; ++c) color.select(2, c).fill_(rgb[c]);
  e.image = umvs::rgb8_to_image_msg(color, e.header);
  e.camera_info = make_info(kPlaneWidth, kPlaneHeight, kPlaneFocal, e.header);
  e.world_frame = "world";
  e.pose = make_pose({x, 0, 0});
  e.depth_min = 1;
  e.depth_max = 5;
  return e;
}

}  // namespace umvs_test
