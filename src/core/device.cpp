#include "unsup_mvs/core/device.h"

#include <torch/torch.h>

#include <stdexcept>
#include <thread>

namespace umvs {

torch::Device parse_device(const std::string& name) {
  torch::Device device(torch::kCPU);
  try {
    device = torch::Device(name);
  } catch (const std::exception&) {
    throw std::invalid_argument("unknown device '" + name + "' (expected cpu, cuda or cuda:N)");
  }
  if (device.is_cuda()) {
    if (!torch::cuda::is_available()) {
      throw std::invalid_argument("device '" + name +
                                  "' requested but this LibTorch has no CUDA or no GPU is visible");
    }
    if (device.has_index() && device.index() >= static_cast<int>(torch::cuda::device_count())) {
      throw std::invalid_argument("device '" + name + "' does not exist (" +
                                  std::to_string(torch::cuda::device_count()) + " GPUs visible)");
    }
  } else if (!device.is_cpu()) {
    throw std::invalid_argument("unsupported device '" + name + "' (expected cpu or cuda)");
  }
  return device;
}

void configure_threads(int threads) {
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(threads);
}

}  // namespace umvs
