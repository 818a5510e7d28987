#include "unsup_mvs/io/ros/ros_conversions.h"

#include <sensor_msgs/image_encodings.h>
#include <tf2_eigen/tf2_eigen.h>
#include <torch/torch.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "unsup_mvs/io/image_io.h"

namespace umvs {

namespace enc = sensor_msgs::image_encodings;

bool is_supported_image_encoding(const std::string& e) {
  return e == enc::RGB8 || e == enc::BGR8 || e == enc::RGBA8 || e == enc::BGRA8 || e == enc::MONO8 || e == enc::MONO16;
}

void check_image_msg(const sensor_msgs::Image& msg, uint64_t max_pixels) {
  const std::string size = std::to_string(msg.width) + "x" + std::to_string(msg.height);
  if (msg.width == 0 || msg.height == 0) throw std::invalid_argument("image has zero size (" + size + ")");
  const uint64_t pixels = static_cast<uint64_t>(msg.width) * msg.height;
  if (pixels > max_pixels) {
    throw std::invalid_argument("image is " + size + " = " + std::to_string(pixels) + " pixels, more than the limit of " +
                                std::to_string(max_pixels));
  }
  uint64_t bytes_per_pixel = 0;
  try {
    bytes_per_pixel = static_cast<uint64_t>(enc::numChannels(msg.encoding)) * enc::bitDepth(msg.encoding) / 8;
  } catch (const std::exception&) {
    throw std::invalid_argument("unknown image encoding '" + msg.encoding + "'");
  }
  // 64-bit products: step * height of a hostile message can overflow 32 bits.
  const uint64_t row = static_cast<uint64_t>(msg.width) * bytes_per_pixel;
  if (msg.step < row) {
    throw std::invalid_argument("image row step " + std::to_string(msg.step) + " is shorter than a " + size + " " +
                                msg.encoding + " row (" + std::to_string(row) + " bytes)");
  }
  const uint64_t needed = static_cast<uint64_t>(msg.step) * msg.height;
  if (msg.data.size() < needed) {
    throw std::invalid_argument("truncated image: " + std::to_string(msg.data.size()) + " bytes of data, step " +
                                std::to_string(msg.step) + " x height " + std::to_string(msg.height) + " needs " +
                                std::to_string(needed) + " (" + size + " " + msg.encoding + ")");
  }
}

namespace {

int channels_of(const std::string& e) {
  if (e == enc::RGB8 || e == enc::BGR8) return 3;
  if (e == enc::RGBA8 || e == enc::BGRA8) return 4;
  return 1;
}

// The pixel rows of `msg` without padding: [H, W*bytes_per_pixel] uint8.
torch::Tensor packed_rows(const sensor_msgs::Image& msg, int bytes_per_pixel) {
  check_image_msg(msg, std::numeric_limits<uint64_t>::max());
  const int64_t H = msg.height, W = msg.width;
  const int64_t row = W * bytes_per_pixel;
  auto out = torch::empty({H, row}, torch::kUInt8);
  for (int64_t y = 0; y < H; ++y) std::memcpy(out[y].data_ptr(), msg.data.data() + y * msg.step, row);
  return out;
}

}  // namespace

torch::Tensor image_msg_to_rgb8(const sensor_msgs::Image& msg) {
  const std::string& e = msg.encoding;
  if (!is_supported_image_encoding(e)) {
    throw std::invalid_argument("unsupported image encoding '" + e +
                                "' (accepted: rgb8, bgr8, rgba8, bgra8, mono8, mono16)");
  }
  const int64_t H = msg.height, W = msg.width;
  if (e == enc::MONO16) {
    auto raw = packed_rows(msg, 2).view({H, W, 2}).to(torch::kInt32);
    const int hi = msg.is_bigendian ? 0 : 1;
    auto v = raw.select(2, hi) * 256 + raw.select(2, 1 - hi);  // [H,W] 0..65535
    auto g = (v.to(torch::kFloat32) / 257.0f).round().clamp(0, 255).to(torch::kUInt8);
    return g.unsqueeze(2).expand({H, W, 3}).contiguous();
  }
  const int c = channels_of(e);
  auto px = packed_rows(msg, c).view({H, W, c});
  if (c == 1) return px.expand({H, W, 3}).contiguous();
  auto rgb = px.slice(2, 0, 3);
  if (e == enc::BGR8 || e == enc::BGRA8) rgb = rgb.flip(2);
  return rgb.contiguous();
}

sensor_msgs::Image compressed_to_image_msg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels) {
  // format: "jpeg", "png", or image_transport's "<encoding>; jpeg compressed <encoding>".
  if (msg.format.find("compressedDepth") != std::string::npos) {
    throw std::invalid_argument("compressed image format '" + msg.format + "' is a depth image, not a camera image");
  }
  if (!msg.format.empty() && msg.format.find("jpeg") == std::string::npos &&
      msg.format.find("jpg") == std::string::npos && msg.format.find("png") == std::string::npos) {
    throw std::invalid_argument("compressed image format '" + msg.format + "' is not jpeg or png");
  }
  torch::Tensor rgb8;
  try {
    rgb8 = decode_image_rgb8(msg.data.data(), msg.data.size(), "compressed image (" + msg.format + ")");
  } catch (const std::runtime_error& e) {
    throw std::invalid_argument(e.what());
  }
  if (static_cast<uint64_t>(rgb8.size(0)) * static_cast<uint64_t>(rgb8.size(1)) > max_pixels) {
    throw std::invalid_argument("compressed image is " + std::to_string(rgb8.size(1)) + "x" + std::to_string(rgb8.size(0)) +
                                ", more than " + std::to_string(max_pixels) + " pixels");
  }
  return rgb8_to_image_msg(rgb8, msg.header);
}

sensor_msgs::Image rgb8_to_image_msg(const torch::Tensor& rgb8, const std_msgs::Header& header) {
  if (!rgb8.defined() || rgb8.dim() != 3 || rgb8.size(2) != 3 || rgb8.scalar_type() != torch::kUInt8) {
    throw std::invalid_argument("rgb8_to_image_msg: need uint8 [H,W,3]");
  }
  auto t = rgb8.contiguous().to(torch::kCPU);
  sensor_msgs::Image m;
  m.header = header;
  m.height = t.size(0);
  m.width = t.size(1);
  m.encoding = enc::RGB8;
  m.is_bigendian = 0;
  m.step = m.width * 3;
  m.data.assign(t.data_ptr<uint8_t>(), t.data_ptr<uint8_t>() + t.numel());
  return m;
}

sensor_msgs::Image float_to_image_msg(const torch::Tensor& values, const std_msgs::Header& header) {
  if (!values.defined() || values.dim() != 2) throw std::invalid_argument("float_to_image_msg: need [H,W]");
  auto t = values.to(torch::kCPU, torch::kFloat32).contiguous();
  sensor_msgs::Image m;
  m.header = header;
  m.height = t.size(0);
  m.width = t.size(1);
  m.encoding = enc::TYPE_32FC1;
  m.is_bigendian = 0;
  m.step = m.width * 4;
  const auto* p = reinterpret_cast<const uint8_t*>(t.data_ptr<float>());
  m.data.assign(p, p + t.numel() * 4);
  return m;
}

sensor_msgs::Image depth_camera_image_msg(const torch::Tensor& depth, const torch::Tensor& confidence,
                                          double min_confidence, const std_msgs::Header& header) {
  if (!depth.defined() || !confidence.defined() || depth.sizes() != confidence.sizes()) {
    throw std::invalid_argument("depth_camera_image_msg: depth and confidence must be [H,W] of one size");
  }
  const auto d = depth.to(torch::kCPU, torch::kFloat32);
  const auto known = (d > 0) & torch::isfinite(d) & (confidence.to(torch::kCPU, torch::kFloat32) >= min_confidence);
  return float_to_image_msg(d.where(known, torch::full({}, std::numeric_limits<float>::quiet_NaN())), header);
}

sensor_msgs::Image depth_camera_image_16uc1_msg(const sensor_msgs::Image& depth_32fc1) {
  const torch::Tensor metres = image_msg_to_float(depth_32fc1);
  const auto mm = (metres * 1000.0f).round();
  const auto known = torch::isfinite(mm) & (mm >= 1.0f) & (mm <= 65535.0f);
  const auto values = mm.where(known, torch::zeros({})).to(torch::kInt32).contiguous();
  sensor_msgs::Image m;
  m.header = depth_32fc1.header;
  m.height = depth_32fc1.height;
  m.width = depth_32fc1.width;
  m.encoding = enc::TYPE_16UC1;
  m.is_bigendian = 0;
  m.step = m.width * 2;
  m.data.resize(static_cast<size_t>(m.step) * m.height);
  const int32_t* v = values.data_ptr<int32_t>();
  for (int64_t i = 0; i < values.numel(); ++i) {  // little-endian, as is_bigendian says
    m.data[2 * i] = static_cast<uint8_t>(v[i] & 0xff);
    m.data[2 * i + 1] = static_cast<uint8_t>((v[i] >> 8) & 0xff);
  }
  return m;
}

torch::Tensor image_msg_to_float(const sensor_msgs::Image& msg) {
  if (msg.encoding != enc::TYPE_32FC1) {
    throw std::invalid_argument("expected a 32FC1 image, got '" + msg.encoding + "'");
  }
  if (msg.is_bigendian) throw std::invalid_argument("big-endian 32FC1 images are not supported");
  auto rows = packed_rows(msg, 4);
  return rows.view(torch::kFloat32).view({static_cast<int64_t>(msg.height), static_cast<int64_t>(msg.width)}).clone();
}

Camera camera_from_info(const sensor_msgs::CameraInfo& info, bool rectified) {
  if (info.width == 0 || info.height == 0) throw std::invalid_argument("camera_info has zero image size");
  if (info.binning_x > 1 || info.binning_y > 1) throw std::invalid_argument("camera_info with binning is not supported");
  if (info.roi.width != 0 && (info.roi.width != info.width || info.roi.height != info.height)) {
    throw std::invalid_argument("camera_info with a region of interest is not supported");
  }
  Camera c;
  c.width = static_cast<int>(info.width);
  c.height = static_cast<int>(info.height);
  const bool has_p = info.P[0] != 0.0 && info.P[5] != 0.0;
  if (rectified && has_p) {
    c.K << info.P[0], info.P[1], info.P[2], info.P[4], info.P[5], info.P[6], info.P[8], info.P[9], info.P[10];
  } else {
    c.K << info.K[0], info.K[1], info.K[2], info.K[3], info.K[4], info.K[5], info.K[6], info.K[7], info.K[8];
  }
  if (!rectified) {
    for (double d : info.D) {
      if (d != 0.0) {
        throw std::invalid_argument("camera_info has non-zero distortion coefficients (model '" + info.distortion_model +
                                    "'); feed rectified images (image_proc image_rect_color) and set rectified:=true");
      }
    }
  }
  c.validate("camera_info");
  return c;
}

sensor_msgs::CameraInfo camera_info_from_camera(const Camera& camera, const std_msgs::Header& header) {
  sensor_msgs::CameraInfo info;
  info.header = header;
  info.width = camera.width;
  info.height = camera.height;
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) {
      info.K[r * 3 + col] = camera.K(r, col);
      info.P[r * 4 + col] = camera.K(r, col);
    }
  }
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  return info;
}

namespace {

// tf2_eigen turns the quaternion into a rotation as given: refuse non-finite poses and quaternions
// far from unit length, and hand it the normalised one.
geometry_msgs::Quaternion checked_rotation(const Eigen::Vector3d& translation, const geometry_msgs::Quaternion& rotation) {
  Eigen::Quaterniond q;
  tf2::fromMsg(rotation, q);
  if (!translation.allFinite() || !q.coeffs().allFinite()) throw std::invalid_argument("pose has non-finite values");
  if (std::abs(q.norm() - 1.0) > 1e-3) {
    throw std::invalid_argument("pose orientation is not a unit quaternion (norm " + std::to_string(q.norm()) + ")");
  }
  return tf2::toMsg(q.normalized());
}

}  // namespace

Eigen::Matrix4d pose_to_matrix(const geometry_msgs::Pose& pose) {
  geometry_msgs::Pose unit = pose;
  unit.orientation = checked_rotation({pose.position.x, pose.position.y, pose.position.z}, pose.orientation);
  Eigen::Isometry3d T;
  tf2::fromMsg(unit, T);
  return T.matrix();
}

Eigen::Matrix4d transform_to_matrix(const geometry_msgs::Transform& transform) {
  const auto& t = transform.translation;
  geometry_msgs::TransformStamped unit;
  unit.transform = transform;
  unit.transform.rotation = checked_rotation({t.x, t.y, t.z}, transform.rotation);
  return tf2::transformToEigen(unit).matrix();
}

geometry_msgs::Pose matrix_to_pose(const Eigen::Matrix4d& T) { return tf2::toMsg(Eigen::Isometry3d(T)); }

geometry_msgs::Transform matrix_to_transform(const Eigen::Matrix4d& T) {
  return tf2::eigenToTransform(Eigen::Isometry3d(T)).transform;
}

Camera posed_camera_from_msgs(const sensor_msgs::CameraInfo& info, const geometry_msgs::Pose& T_world_camera,
                              bool rectified) {
  return posed_camera_from_msgs(info, pose_to_matrix(T_world_camera), rectified);
}

Camera posed_camera_from_msgs(const sensor_msgs::CameraInfo& info, const Eigen::Matrix4d& T_world_camera, bool rectified) {
  Camera camera = camera_from_info(info, rectified);
  camera.T_cam_world = T_world_camera.inverse();
  camera.validate();
  return camera;
}

PosedImage posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                 const geometry_msgs::Pose& T_world_camera, bool rectified) {
  return posed_image_from_msgs(image, info, pose_to_matrix(T_world_camera), rectified);
}

PosedImage checked_posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                         const geometry_msgs::Pose& T_world_camera, bool rectified, uint64_t max_pixels,
                                         const std::string& name) {
  try {
    check_image_msg(image, max_pixels);
    return posed_image_from_msgs(image, info, T_world_camera, rectified);
  } catch (const std::exception& e) {
    throw std::invalid_argument(name + ": " + e.what());
  }
}

PosedImage posed_image_from_msgs(const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                                 const Eigen::Matrix4d& T_world_camera, bool rectified) {
  PosedImage out;
  out.stamp = image.header.stamp.toSec();
  out.camera = posed_camera_from_msgs(info, T_world_camera, rectified);
  out.image = image_msg_to_rgb8(image);
  if (out.image.size(0) != out.camera.height || out.image.size(1) != out.camera.width) {
    throw std::invalid_argument("image size " + std::to_string(out.image.size(1)) + "x" +
                                std::to_string(out.image.size(0)) + " differs from its CameraInfo's " +
                                std::to_string(out.camera.width) + "x" + std::to_string(out.camera.height));
  }
  return out;
}

}  // namespace umvs
