// The inference nodelet's online pose refinement (~pose_refinement_deg > 0): keyframe sets are served
// with the cameras umvs::KeyframePoseRefiner corrects, and the depth map made from them is published
// in the refined camera's frame. The network sees the reference camera turned by the refinement, so
// the map belongs to that camera, not to the one the robot's tf tree holds: every output of such a
// map (DepthEstimate, depth, confidence, the depth camera topics) names the optical frame
// "<optical frame>_refined", and tf gets world_frame -> "<optical frame>_refined" at the image's
// stamp with the pose the estimate carries to fusion. depth_image_proc's clouds, the fused cloud and
// the occupancy map then agree.
#pragma once

#include <geometry_msgs/Pose.h>
#include <std_msgs/Header.h>
#include <tf2_ros/transform_broadcaster.h>

#include <string>
#include <vector>

#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/keyframe_pose_refiner.h"

namespace umvs_ros {

inline constexpr char kRefinedFrameSuffix[] = "_refined";

class OnlinePoseRefinement {
 public:
  // Advertises /tf at once: a publisher's first message would not reach subscribers still connecting.
  explicit OnlinePoseRefinement(const umvs::KeyframePoseRefinerConfig& config) : refiner_(config) {}

  // Corrects the set's cameras (views[0] the reference, then its sources) and says whether it did: a
  // set without an id per source is served with its poses as given, with a warning.
  bool correct(umvs::DepthEstimator& estimator, const unsup_mvs::KeyframeSet& set, std::vector<umvs::ViewInput>* views);

  // "N pairs over M keyframes": what the refinement knows.
  std::string summary() const;

  // Renames header's optical frame to its refined one and sends world_frame -> that frame at the
  // header's stamp with `pose` (T_world_camera). A header without a frame, or no world frame, is
  // left as it is and nothing is sent.
  void place(const std::string& world_frame, const geometry_msgs::Pose& pose, std_msgs::Header* header);

 private:
  umvs::KeyframePoseRefiner refiner_;
  tf2_ros::TransformBroadcaster broadcaster_;
};

}  // namespace umvs_ros
