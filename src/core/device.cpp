#include "unsup_mvs/core/device.h"

#include <torch/torch.h>

#include <dlfcn.h>
#include <malloc.h>

#include <ATen/Parallel.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <mutex>
#include <set>
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
  tune_cpu_process();
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(threads);
}

std::string tune_cpu_process() {
  static std::once_flag once;
  static std::string done;
  std::call_once(once, [] {
    using SetThreads = void (*)(int);
    if (auto set_threads = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) {
      set_threads(1);
      done += "OpenBLAS threads 1; ";
    }
    // Blocks above M_MMAP_THRESHOLD (at most 32 MiB) are mmapped and unmapped on free, and the heap
    // top is returned to the kernel above M_TRIM_THRESHOLD: a cost volume is hundreds of MiB, so
    // every forward pass would fault all its pages in again (17% of the CPU time at 320x256).
    if (mallopt(M_MMAP_MAX, 0) == 1 && mallopt(M_TRIM_THRESHOLD, INT_MAX) == 1) done += "malloc without mmap or trimming";
    // One arena for all threads: kept heaps per OpenMP worker thread (each keeping its peak, as
    // above) raised the peak memory of a 640x512 forward pass from about 515 to 700 MiB.
    if (mallopt(M_ARENA_MAX, 1) == 1) done += ", one arena";
  });
  return done;
}

int parallel_loop_threads() {
  const int64_t tasks = std::max(1, torch::get_num_threads());
  std::mutex mutex;
  std::set<std::thread::id> seen;
  // One chunk per thread; each waits a little so that one thread cannot take every chunk.
  at::parallel_for(0, tasks, 1, [&](int64_t, int64_t) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      seen.insert(std::this_thread::get_id());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  });
  return static_cast<int>(seen.size());
}

}  // namespace umvs
