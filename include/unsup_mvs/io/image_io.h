// Image files (OpenCV; stb_image in portable builds without OpenCV).
#pragma once

#include <torch/types.h>

#include <string>

namespace umvs {

// Any 8/16-bit grey, RGB or RGBA file -> uint8 [H,W,3] RGB (grey is replicated, 16-bit is
// scaled to 8 bits, alpha dropped). Throws std::runtime_error naming the file.
torch::Tensor read_image_rgb8(const std::string& path);
// 16-bit single-channel PNG (depth images) -> int32 [H,W] raw values.
torch::Tensor read_image_u16(const std::string& path);
// uint8 [H,W,3] RGB or [H,W] grey -> PNG (atomically).
void write_png(const std::string& path, const torch::Tensor& image_u8);
// uint16 data held in an int32 [H,W] tensor -> 16-bit PNG.
void write_png_u16(const std::string& path, const torch::Tensor& values);

}  // namespace umvs
