// Choosing where LibTorch runs.
#pragma once

#include <torch/types.h>

#include <string>

namespace umvs {

// "cpu", "cuda" or "cuda:N". Throws std::invalid_argument with a clear message when CUDA is
// requested but this LibTorch has no CUDA or no device is visible.
torch::Device parse_device(const std::string& name);

// LibTorch defaults to one intra-op thread in some builds: set it explicitly. threads <= 0 means
// all hardware threads.
void configure_threads(int threads);

}  // namespace umvs
