// Pinhole camera: intrinsics, world-to-camera pose and image size. Eigen only (no LibTorch), so
// ROS code and tools can use it cheaply.
//
// Conventions (the same as MVSNet and OpenCV):
//  * pixel (u, v) = (column, row); (0, 0) is the centre of the top-left pixel;
//  * K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]; fy may be negative (e.g. ICL-NUIM);
//  * T_cam_world maps world points into the camera frame (x right, y down, z forward);
//  * depth is z in the camera frame, not the length of the ray.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>

namespace umvs {

constexpr double kRadiansPerDegree = 3.14159265358979323846 / 180.0;  // for Camera::turned

struct Camera {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix4d T_cam_world = Eigen::Matrix4d::Identity();
  int width = 0;
  int height = 0;

  Eigen::Matrix3d R() const { return T_cam_world.topLeftCorner<3, 3>(); }
  Eigen::Vector3d t() const { return T_cam_world.topRightCorner<3, 1>(); }
  Eigen::Matrix4d T_world_cam() const;
  Eigen::Vector3d center() const;  // camera centre in world coordinates
  Eigen::Vector3d viewing_direction() const;  // optical axis in world coordinates
  // P = K [R | t] (3x4).
  Eigen::Matrix<double, 3, 4> projection() const;

  // World point -> pixel. Returns false when the point is not in front of the camera.
  bool project(const Eigen::Vector3d& X_world, Eigen::Vector2d* uv, double* depth = nullptr) const;
  // Pixel + z-depth -> world point.
  Eigen::Vector3d backproject(double u, double v, double depth) const;
  bool in_image(const Eigen::Vector2d& uv, double border = 0.0) const;

  // A camera at `eye` looking at `target` (optical frame as REP 103: x right, y down, z forward),
  // with the image's x axis along forward x up, so that `up` points up in the image. When forward
  // is parallel to `up`, x is the world x axis (or y) made orthogonal to forward.
  static Camera look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Matrix3d& K,
                        int width, int height, const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

  // The same camera for an image resized to new_width x new_height (pixel centres are mapped,
  // so cx' = (cx + 0.5) * sx - 0.5).
  Camera resized(int new_width, int new_height) const;
  // The same camera for the crop whose top-left pixel is (x0, y0) of this image.
  Camera cropped(int x0, int y0, int new_width, int new_height) const;
  // This camera turned about its own centre by the rotation vector `angles` (radians, axis times
  // angle, in this camera's frame).
  Camera turned(const Eigen::Vector3d& angles) const;

  // Throws std::invalid_argument naming the problem: non-finite values, zero focal length,
  // K not upper triangular with K(2,2) = 1, a rotation that is not orthonormal, bad image size.
  // `what` names the camera in the message (e.g. a file name).
  void validate(const std::string& what = "camera") const;
};

// Size (multiple of `multiple`, no larger than max_width x max_height, 0 = no limit) to which an
// image is scaled then centre-cropped for the network, keeping the aspect ratio as far as the
// multiple allows. Returns the resized camera; *scaled_w/h receive the intermediate size.
struct NetworkResize {
  int scaled_width = 0, scaled_height = 0;  // after resizing
  int crop_x = 0, crop_y = 0;               // crop offset in the resized image
  int width = 0, height = 0;                // final size (multiples of `multiple`)
};
NetworkResize plan_network_resize(int width, int height, int max_width, int max_height,
                                  int multiple = 32);
Camera apply_network_resize(const Camera& camera, const NetworkResize& plan);

// Largest entry of |R^T R - I|: how far a matrix read from a file is from a rotation.
double orthonormality_error(const Eigen::Matrix3d& R);
// The rotation nearest to R in the Frobenius norm (U V^T of its SVD, with det +1). Pose files
// written with few digits (7-Scenes: R^T R - I up to 1e-4) hold almost-rotations.
Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& R);
// Camera::validate accepts rotations whose R^T R is the identity to this precision. Pose files off
// by more, up to kMaxRotationRepairError, are re-orthonormalised with a warning (files within
// the tolerance are read as written, bit for bit); more is refused as not a rotation.
constexpr double kRotationTolerance = 1e-4;
constexpr double kMaxRotationRepairError = 1e-2;

// Rotation angle (radians) between two rotation matrices.
double rotation_angle(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);

}  // namespace umvs
