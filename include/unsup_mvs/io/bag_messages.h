// ROS message <-> core type conversions, shared by the bag reader/writer and the nodes. Only in
// the ROS build (files named bag_* are left out of the portable build).
#pragma once

#include <geometry_msgs/Pose.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <torch/types.h>

#include <string>

#include "unsup_mvs/core/camera.h"

namespace umvs {

// Encodings the pipeline accepts for camera images.
bool is_supported_image_encoding(const std::string& encoding);  // rgb8, bgr8, rgba8, bgra8, mono8, mono16

// Checks that the message's data holds what its header claims: a known encoding, a non-zero size
// of at most `max_pixels`, a row step of at least a row, and step * height <= data.size() (a
// truncated image is refused where it enters, not when it poisons later depth maps). Throws
// std::invalid_argument naming the problem.
void check_image_msg(const sensor_msgs::Image& msg, uint64_t max_pixels);

// sensor_msgs/Image -> uint8 [H,W,3] RGB (grey replicated, mono16 scaled to 8 bits, alpha dropped;
// row padding and big-endian mono16 handled). Throws std::invalid_argument naming the encoding or
// the size mismatch.
torch::Tensor image_msg_to_rgb8(const sensor_msgs::Image& msg);
// uint8 [H,W,3] RGB -> rgb8 image.
sensor_msgs::Image rgb8_to_image_msg(const torch::Tensor& rgb8, const std_msgs::Header& header);
// float32 [H,W] -> 32FC1 image (depth in metres, REP 118).
sensor_msgs::Image float_to_image_msg(const torch::Tensor& values, const std_msgs::Header& header);
// 32FC1 image -> float32 [H,W]. Throws std::invalid_argument for another encoding.
torch::Tensor image_msg_to_float(const sensor_msgs::Image& msg);

// CameraInfo -> intrinsics and size (T_cam_world = identity). With `rectified` the image is taken
// as rectified (image_proc's image_rect*) and P's left 3x3 gives K; otherwise K is used and
// non-zero distortion coefficients are refused (the network assumes a pinhole). Binning and ROI
// are refused. Throws std::invalid_argument naming the problem.
Camera camera_from_info(const sensor_msgs::CameraInfo& info, bool rectified);
// Pinhole CameraInfo (no distortion, P = [K | 0]) of a camera.
sensor_msgs::CameraInfo camera_info_from_camera(const Camera& camera, const std_msgs::Header& header);

// geometry_msgs/Pose <-> 4x4 rigid transform (T_world_camera for camera poses). pose_to_matrix
// throws std::invalid_argument for a non-finite pose or a quaternion far from unit length.
Eigen::Matrix4d pose_to_matrix(const geometry_msgs::Pose& pose);
geometry_msgs::Pose matrix_to_pose(const Eigen::Matrix4d& T);

}  // namespace umvs
