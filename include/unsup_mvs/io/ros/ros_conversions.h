// ROS message <-> core type conversions, shared by the nodes and the bag reader/writer. Only in
// the ROS build (io/ros/ is left out of the portable build).
#pragma once

#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
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
// sensor_msgs/CompressedImage (jpeg or png, what image_transport's `compressed` transport and
// most camera drivers' bags carry) -> rgb8 image with the same header, at most `max_pixels`.
// Throws std::invalid_argument naming the problem (compressedDepth, another format, a corrupt or
// oversized image).
sensor_msgs::Image compressed_to_image_msg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels);
// uint8 [H,W,3] RGB -> rgb8 image.
sensor_msgs::Image rgb8_to_image_msg(const torch::Tensor& rgb8, const std_msgs::Header& header);
// float32 [H,W] -> 32FC1 image (depth in metres, REP 118).
sensor_msgs::Image float_to_image_msg(const torch::Tensor& values, const std_msgs::Header& header);
// The depth map as a standard depth camera image (REP 118): 32FC1 metres, NaN where there is no
// estimate (depth <= 0 or not finite) or the confidence is below min_confidence, so that
// depth_image_proc and other consumers drop those pixels. depth, confidence: float32 [H,W].
sensor_msgs::Image depth_camera_image_msg(const torch::Tensor& depth, const torch::Tensor& confidence,
                                          double min_confidence, const std_msgs::Header& header);
// The same depth camera image as 16UC1 millimetres (OpenNI's raw depth, what rtabmap and
// depth_image_proc/convert_metric take): 0 where 32FC1 has NaN, and where the depth is beyond
// 65.535 m or rounds to 0 mm.
sensor_msgs::Image depth_camera_image_16uc1_msg(const sensor_msgs::Image& depth_32fc1);
// 32FC1 image -> float32 [H,W]. Throws std::invalid_argument for another encoding.
torch::Tensor image_msg_to_float(const sensor_msgs::Image& msg);

// CameraInfo -> intrinsics and size (T_cam_world = identity). With `rectified` the image is taken
// as rectified (image_proc's image_rect*) and P's left 3x3 gives K; otherwise K is used and
// non-zero distortion coefficients are refused (the network assumes a pinhole). Binning and ROI
// are refused. Throws std::invalid_argument naming the problem.
Camera camera_from_info(const sensor_msgs::CameraInfo& info, bool rectified);
// Pinhole CameraInfo (no distortion, P = [K | 0]) of a camera.
sensor_msgs::CameraInfo camera_info_from_camera(const Camera& camera, const std_msgs::Header& header);

// Rigid transforms of geometry_msgs and tf2 <-> 4x4 matrices, through tf2_eigen. For a camera the
// matrix is T_world_camera, the camera's pose in the world (REP 103); a tf2 transform parent -> child
// is the child's pose in the parent frame. The readers throw std::invalid_argument for non-finite
// values or a quaternion far from unit length (a nearly unit one is normalised).
Eigen::Matrix4d pose_to_matrix(const geometry_msgs::Pose& pose);
Eigen::Matrix4d transform_to_matrix(const geometry_msgs::Transform& transform);
geometry_msgs::Pose matrix_to_pose(const Eigen::Matrix4d& T);
geometry_msgs::Transform matrix_to_transform(const Eigen::Matrix4d& T);

// A calibrated, posed image as the pipeline uses it.
struct PosedImage {
  double stamp = 0.0;    // seconds
  torch::Tensor image;   // uint8 [H,W,3] RGB
  Camera camera;         // intrinsics, size and T_cam_world
  torch::Tensor depth;   // float32 [H,W] metres, when a bag's depth topic is set and has a message at the stamp
};

// The camera of an image from its CameraInfo (see camera_from_info) and its pose T_world_camera
// (the optical frame's pose in the world, REP 103), validated. Throws std::invalid_argument.
Camera posed_camera_from_msgs(const sensor_msgs::CameraInfo& info, const geometry_msgs::Pose& T_world_camera,
                              bool rectified);
Camera posed_camera_from_msgs(const sensor_msgs::CameraInfo& info, const Eigen::Matrix4d& T_world_camera, bool rectified);
// The same plus the image as rgb8, which must have the CameraInfo's size (the image is not checked
// against a pixel budget here: check_image_msg first where a bound applies). Throws
// std::invalid_argument.
PosedImage posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                 const geometry_msgs::Pose& T_world_camera, bool rectified);
PosedImage posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                 const Eigen::Matrix4d& T_world_camera, bool rectified);
// An image of a message the node received: check_image_msg(image, max_pixels), then the above;
// the error names the view (`name`: "reference", "source 12") before the problem.
PosedImage checked_posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                         const geometry_msgs::Pose& T_world_camera, bool rectified, uint64_t max_pixels,
                                         const std::string& name);

}  // namespace umvs
