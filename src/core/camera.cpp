#include "unsup_mvs/core/camera.h"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace umvs {

Eigen::Matrix4d Camera::T_world_cam() const {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = R().transpose();
  T.topRightCorner<3, 1>() = -R().transpose() * t();
  return T;
}

Eigen::Vector3d Camera::center() const { return -R().transpose() * t(); }

Camera Camera::turned(const Eigen::Vector3d& angles) const {
  Camera out = *this;
  const double angle = angles.norm();
  if (angle == 0.0) return out;
  const Eigen::Matrix3d turn = Eigen::AngleAxisd(angle, angles / angle).toRotationMatrix();
  out.T_cam_world.topRows<3>() = turn * T_cam_world.topRows<3>();  // X_cam' = turn * X_cam: the centre stays
  return out;
}

Eigen::Vector3d Camera::viewing_direction() const { return R().row(2).transpose(); }

Eigen::Matrix<double, 3, 4> Camera::projection() const {
  return K * T_cam_world.topRows<3>();
}

bool Camera::project(const Eigen::Vector3d& X_world, Eigen::Vector2d* uv, double* depth) const {
  const Eigen::Vector3d Xc = R() * X_world + t();
  if (depth) *depth = Xc.z();
  if (!(Xc.z() > 0.0)) return false;
  const Eigen::Vector3d p = K * Xc;
  if (uv) *uv = p.head<2>() / p.z();
  return true;
}

Eigen::Vector3d Camera::backproject(double u, double v, double depth) const {
  const Eigen::Vector3d ray = K.inverse() * Eigen::Vector3d(u, v, 1.0);
  const Eigen::Vector3d Xc = ray * depth;  // ray.z() == 1, so Xc.z() == depth
  return R().transpose() * (Xc - t());
}

bool Camera::in_image(const Eigen::Vector2d& uv, double border) const {
  return uv.x() >= -0.5 + border && uv.y() >= -0.5 + border && uv.x() <= width - 0.5 - border &&
         uv.y() <= height - 0.5 - border;
}

Camera Camera::look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Matrix3d& K,
                       int width, int height, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up.normalized());
  if (x.norm() < 1e-6) {  // looking along `up`
    const Eigen::Vector3d axis = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    x = axis - axis.dot(z) * z;
  }
  x.normalize();
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.K = K;
  Eigen::Matrix3d R;
  R.row(0) = x.transpose();
  R.row(1) = z.cross(x).transpose();
  R.row(2) = z.transpose();
  cam.T_cam_world.setIdentity();
  cam.T_cam_world.topLeftCorner<3, 3>() = R;
  cam.T_cam_world.topRightCorner<3, 1>() = -R * eye;
  return cam;
}

Camera Camera::resized(int new_width, int new_height) const {
  if (width <= 0 || height <= 0) throw std::invalid_argument("Camera::resized: camera has no image size");
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  Camera c = *this;
  c.K.row(0) *= sx;
  c.K.row(1) *= sy;
  c.K(0, 2) = (K(0, 2) + 0.5) * sx - 0.5;
  c.K(1, 2) = (K(1, 2) + 0.5) * sy - 0.5;
  c.width = new_width;
  c.height = new_height;
  return c;
}

Camera Camera::cropped(int x0, int y0, int new_width, int new_height) const {
  Camera c = *this;
  c.K(0, 2) -= x0;
  c.K(1, 2) -= y0;
  c.width = new_width;
  c.height = new_height;
  return c;
}

void Camera::validate(const std::string& what) const {
  auto fail = [&](const std::string& msg) { throw std::invalid_argument(what + ": " + msg); };
  if (!K.allFinite()) fail("intrinsics contain NaN or infinity");
  if (!T_cam_world.allFinite()) fail("pose contains NaN or infinity");
  if (std::abs(K(0, 0)) < 1e-9 || std::abs(K(1, 1)) < 1e-9) fail("focal length is zero");
  if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || std::abs(K(2, 2) - 1.0) > 1e-9) {
    std::ostringstream os;
    os << "intrinsics are not of the form [[fx,s,cx],[0,fy,cy],[0,0,1]]:\n" << K;
    fail(os.str());
  }
  const Eigen::Matrix3d RtR = R().transpose() * R();
  if (!RtR.isIdentity(kRotationTolerance) || R().determinant() < 0.0) {
    std::ostringstream os;
    os << "rotation of the world-to-camera pose is not a proper rotation (R^T R - I max "
       << (RtR - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() << ", det " << R().determinant()
       << ")";
    fail(os.str());
  }
  if (T_cam_world.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) fail("last row of the pose is not [0 0 0 1]");
  if (width < 0 || height < 0) fail("negative image size");
}

NetworkResize plan_network_resize(int width, int height, int max_width, int max_height, int multiple) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("plan_network_resize: empty image");
  double scale = 1.0;
  if (max_width > 0) scale = std::min(scale, static_cast<double>(max_width) / width);
  if (max_height > 0) scale = std::min(scale, static_cast<double>(max_height) / height);
  NetworkResize plan;
  plan.scaled_width = std::max(1, static_cast<int>(std::lround(width * scale)));
  plan.scaled_height = std::max(1, static_cast<int>(std::lround(height * scale)));
  plan.width = plan.scaled_width / multiple * multiple;
  plan.height = plan.scaled_height / multiple * multiple;
  if (plan.width == 0 || plan.height == 0) {
    throw std::invalid_argument("image of " + std::to_string(width) + "x" + std::to_string(height) +
                                " is too small for the network (needs at least " +
                                std::to_string(multiple) + " pixels each way)");
  }
  plan.crop_x = (plan.scaled_width - plan.width) / 2;
  plan.crop_y = (plan.scaled_height - plan.height) / 2;
  return plan;
}

Camera apply_network_resize(const Camera& camera, const NetworkResize& plan) {
  Camera c = camera;
  if (plan.scaled_width != camera.width || plan.scaled_height != camera.height) {
    c = c.resized(plan.scaled_width, plan.scaled_height);
  }
  return c.cropped(plan.crop_x, plan.crop_y, plan.width, plan.height);
}

double orthonormality_error(const Eigen::Matrix3d& R) {
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& R) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

double rotation_angle(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  const double c = std::clamp(((Ra.transpose() * Rb).trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c);
}

}  // namespace umvs
