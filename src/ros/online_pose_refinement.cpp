#include "unsup_mvs/ros/online_pose_refinement.h"

#include <geometry_msgs/TransformStamped.h>
#include <ros/console.h>

namespace umvs_ros {

bool OnlinePoseRefinement::correct(umvs::DepthEstimator& estimator, const unsup_mvs::KeyframeSet& set,
                                   std::vector<umvs::ViewInput>* views) {
  if (set.source_ids.size() != set.source_images.size()) {
    ROS_WARN_THROTTLE(10.0, "inference: keyframe set %u has %zu source ids for %zu sources; its poses are not refined",
                      set.reference_id, set.source_ids.size(), set.source_images.size());
    return false;
  }
  std::vector<int64_t> ids{static_cast<int64_t>(set.reference_id)};
  for (const auto id : set.source_ids) ids.push_back(static_cast<int64_t>(id));
  *views = refiner_.correct(estimator, ids, std::move(*views), set.depth_min, set.depth_max);
  const Eigen::Vector3d turn = refiner_.turn_degrees(ids.front());
  ROS_DEBUG("inference: keyframe %u: %d new pair measurements, %s; reference turned by (%.2f, %.2f, %.2f) deg",
            set.reference_id, refiner_.last_new_measurements(), summary().c_str(), turn.x(), turn.y(), turn.z());
  return true;
}

std::string OnlinePoseRefinement::summary() const {
  return std::to_string(refiner_.measured_pairs()) + " pairs over " + std::to_string(refiner_.keyframes()) +
         " keyframes";
}

void OnlinePoseRefinement::place(const std::string& world_frame, const geometry_msgs::Pose& pose,
                                 std_msgs::Header* header) {
  if (header->frame_id.empty() || world_frame.empty()) return;
  header->frame_id += kRefinedFrameSuffix;
  geometry_msgs::TransformStamped tf;
  tf.header.stamp = header->stamp;
  tf.header.frame_id = world_frame;
  tf.child_frame_id = header->frame_id;
  tf.transform.translation.x = pose.position.x;
  tf.transform.translation.y = pose.position.y;
  tf.transform.translation.z = pose.position.z;
  tf.transform.rotation = pose.orientation;
  broadcaster_.sendTransform(tf);
}

}  // namespace umvs_ros
