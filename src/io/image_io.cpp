#include "unsup_mvs/io/image_io.h"

#include <torch/torch.h>

#include <algorithm>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"

#if defined(UMVS_HAVE_OPENCV)
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#elif defined(UMVS_HAVE_STB)
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image.h>
#include <stb_image_write.h>
#endif

namespace umvs {

namespace fail_msg {
[[noreturn]] void unsupported(const std::string& path) {
  throw std::runtime_error("cannot read image '" + path +
                           "': this build has no image decoder (built without OpenCV and stb_image)");
}
}  // namespace fail_msg

#if defined(UMVS_HAVE_OPENCV) || defined(UMVS_HAVE_STB)
namespace {
// Before decoding: a regular file of bounded size whose header (PNG, JPEG) promises a bounded
// image, so that a small file claiming 100000x100000 pixels is refused instead of decoded.
void check_image_file(const std::string& path) {
  checked_file_size(path, kMaxImageFileBytes, "image");
  int width = 0, height = 0;
  if (probe_image_size(path, &width, &height)) check_image_pixels(width, height, "image '" + path + "'");
}
// The same bounds for an encoded image in memory.
void check_encoded_image(const uint8_t* data, size_t size, const std::string& what) {
  if (size == 0) throw std::runtime_error(what + " is empty");
  if (size > static_cast<size_t>(kMaxImageFileBytes)) {
    throw std::runtime_error(what + " has " + std::to_string(size) + " bytes, more than the " +
                             std::to_string(kMaxImageFileBytes >> 20) + " MiB accepted for one image");
  }
  int width = 0, height = 0;
  const std::string head(reinterpret_cast<const char*>(data), std::min<size_t>(size, 64 * 1024));
  if (probe_image_header(head, &width, &height)) check_image_pixels(width, height, what);
}
}  // namespace
#endif

#if defined(UMVS_HAVE_OPENCV)

namespace {
// A decoded image (BGR order, as OpenCV gives it) -> uint8 [H,W,3] RGB.
torch::Tensor mat_to_rgb8(cv::Mat img, const std::string& what) {
  check_image_pixels(img.cols, img.rows, what);
  if (img.depth() == CV_16U) img.convertTo(img, CV_8U, 1.0 / 257.0);
  if (img.depth() != CV_8U) throw std::runtime_error(what + " has an unsupported pixel type");
  cv::Mat rgb;
  switch (img.channels()) {
    case 1: cv::cvtColor(img, rgb, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(img, rgb, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(img, rgb, cv::COLOR_BGRA2RGB); break;
    default: throw std::runtime_error(what + " has " + std::to_string(img.channels()) + " channels");
  }
  return torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kUInt8).clone();
}
}  // namespace

torch::Tensor read_image_rgb8(const std::string& path) {
  check_image_file(path);
  cv::Mat img = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (img.empty()) throw std::runtime_error("cannot read image '" + path + "' (missing or not an image)");
  return mat_to_rgb8(img, "image '" + path + "'");
}

torch::Tensor decode_image_rgb8(const uint8_t* data, size_t size, const std::string& what) {
  check_encoded_image(data, size, what);
  const cv::Mat encoded(1, static_cast<int>(size), CV_8UC1, const_cast<uint8_t*>(data));
  cv::Mat img = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
  if (img.empty()) throw std::runtime_error(what + " cannot be decoded (not a PNG or JPEG?)");
  return mat_to_rgb8(img, what);
}

torch::Tensor read_image_u16(const std::string& path) {
  check_image_file(path);
  cv::Mat img = cv::imread(path, cv::IMREAD_ANYDEPTH);
  if (img.empty()) throw std::runtime_error("cannot read image '" + path + "' (missing or not an image)");
  check_image_pixels(img.cols, img.rows, "image '" + path + "'");
  if (img.channels() != 1) throw std::runtime_error("image '" + path + "' is not single-channel");
  img.convertTo(img, CV_32S);
  return torch::from_blob(img.data, {img.rows, img.cols}, torch::kInt32).clone();
}

namespace {
void write_mat(const std::string& path, const cv::Mat& mat) {
  std::vector<uchar> buf;
  if (!cv::imencode(".png", mat, buf)) throw std::runtime_error("cannot encode PNG for '" + path + "'");
  write_file_atomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(buf.size()));
  });
}
}  // namespace

void write_png(const std::string& path, const torch::Tensor& image_u8) {
  auto t = image_u8.to(torch::kCPU, torch::kUInt8).contiguous();
  if (t.dim() == 2) {
    write_mat(path, cv::Mat(t.size(0), t.size(1), CV_8UC1, t.data_ptr()));
  } else if (t.dim() == 3 && t.size(2) == 3) {
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(t.size(0), t.size(1), CV_8UC3, t.data_ptr()), bgr, cv::COLOR_RGB2BGR);
    write_mat(path, bgr);
  } else {
    throw std::invalid_argument("write_png: expected [H,W] or [H,W,3] uint8");
  }
}

void write_png_u16(const std::string& path, const torch::Tensor& values) {
  auto t = values.to(torch::kCPU, torch::kInt32).clamp(0, 65535).contiguous();
  cv::Mat m(t.size(0), t.size(1), CV_32SC1, t.data_ptr());
  cv::Mat m16;
  m.convertTo(m16, CV_16U);
  write_mat(path, m16);
}

#elif defined(UMVS_HAVE_STB)

torch::Tensor read_image_rgb8(const std::string& path) {
  check_image_file(path);
  int w, h, c;
  unsigned char* data = stbi_load(path.c_str(), &w, &h, &c, 3);
  if (!data) throw std::runtime_error("cannot read image '" + path + "': " + stbi_failure_reason());
  auto out = torch::from_blob(data, {h, w, 3}, torch::kUInt8).clone();
  stbi_image_free(data);
  return out;
}

torch::Tensor decode_image_rgb8(const uint8_t* bytes, size_t size, const std::string& what) {
  check_encoded_image(bytes, size, what);
  int w, h, c;
  unsigned char* data = stbi_load_from_memory(bytes, static_cast<int>(size), &w, &h, &c, 3);
  if (!data) throw std::runtime_error(what + " cannot be decoded: " + stbi_failure_reason());
  auto out = torch::from_blob(data, {h, w, 3}, torch::kUInt8).clone();
  stbi_image_free(data);
  return out;
}

torch::Tensor read_image_u16(const std::string& path) {
  check_image_file(path);
  int w, h, c;
  unsigned short* data = stbi_load_16(path.c_str(), &w, &h, &c, 1);
  if (!data) throw std::runtime_error("cannot read image '" + path + "': " + stbi_failure_reason());
  auto out = torch::from_blob(data, {h, w}, torch::kInt16).clone().to(torch::kInt32).bitwise_and(0xffff);
  stbi_image_free(data);
  return out;
}

void write_png(const std::string& path, const torch::Tensor& image_u8) {
  auto t = image_u8.to(torch::kCPU, torch::kUInt8).contiguous();
  const int channels = t.dim() == 2 ? 1 : static_cast<int>(t.size(2));
  int len = 0;
  unsigned char* png = stbi_write_png_to_mem(t.data_ptr<uint8_t>(), static_cast<int>(t.size(1)) * channels,
                                             static_cast<int>(t.size(1)), static_cast<int>(t.size(0)), channels, &len);
  if (!png) throw std::runtime_error("cannot encode PNG for '" + path + "'");
  write_file_atomically(path, [&](std::ostream& out) { out.write(reinterpret_cast<const char*>(png), len); });
  STBIW_FREE(png);
}

void write_png_u16(const std::string& path, const torch::Tensor&) {
  throw std::runtime_error("writing 16-bit PNG '" + path + "' needs OpenCV");
}

#else

torch::Tensor read_image_rgb8(const std::string& path) { fail_msg::unsupported(path); }
torch::Tensor read_image_u16(const std::string& path) { fail_msg::unsupported(path); }
torch::Tensor decode_image_rgb8(const uint8_t*, size_t, const std::string& what) { fail_msg::unsupported(what); }
void write_png(const std::string& path, const torch::Tensor&) { fail_msg::unsupported(path); }
void write_png_u16(const std::string& path, const torch::Tensor&) { fail_msg::unsupported(path); }

#endif

}  // namespace umvs
