// Image files (OpenCV; stb_image in portable builds without OpenCV).
#pragma once

#include <torch/types.h>

#include <cstddef>
#include <cstdint>
#include <string>

namespace umvs {

// Any 8/16-bit grey, RGB or RGBA file -> uint8 [H,W,3] RGB (grey is replicated, 16-bit is
// scaled to 8 bits, alpha dropped). Throws std::runtime_error naming the file.
torch::Tensor read_image_rgb8(const std::string& path);
// An encoded PNG or JPEG in memory (a sensor_msgs/CompressedImage's data) -> uint8 [H,W,3] RGB as
// read_image_rgb8 gives it. The size its header promises is bounded before decoding. Throws
// std::runtime_error naming `what`.
torch::Tensor decode_image_rgb8(const uint8_t* data, size_t size, const std::string& what);
// 16-bit single-channel PNG (depth images) -> int32 [H,W] raw values.
torch::Tensor read_image_u16(const std::string& path);
// uint8 [H,W,3] RGB or [H,W] grey -> PNG (atomically).
void write_png(const std::string& path, const torch::Tensor& image_u8);
// uint16 data held in an int32 [H,W] tensor -> 16-bit PNG.
void write_png_u16(const std::string& path, const torch::Tensor& values);

}  // namespace umvs
