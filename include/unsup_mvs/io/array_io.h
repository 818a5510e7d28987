// Dense arrays on disk: NumPy .npy (v1/v2, little-endian, C order) and PFM.
#pragma once

#include <torch/types.h>

#include <string>

namespace umvs {

// Reads float32, float64, uint8, int32 and int64 arrays. Throws std::runtime_error naming the file
// and the problem (bad magic, unsupported dtype, Fortran order, truncated data).
torch::Tensor read_npy(const std::string& path);
// Writes float32, float64, uint8, int32 or int64 tensors (made contiguous on the CPU), atomically.
void write_npy(const std::string& path, const torch::Tensor& tensor);

// PFM: "Pf" greyscale -> [H,W] float32, "PF" colour -> [H,W,3]; rows stored bottom to top.
torch::Tensor read_pfm(const std::string& path);
// Writes [H,W] (Pf) or [H,W,3] (PF) little-endian float32, atomically.
void write_pfm(const std::string& path, const torch::Tensor& image);

}  // namespace umvs
