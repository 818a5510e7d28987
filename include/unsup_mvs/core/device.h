// Choosing where LibTorch runs.
#pragma once

#include <torch/types.h>

#include <string>

namespace umvs {

// "cpu", "cuda" or "cuda:N". Throws std::invalid_argument with a clear message when CUDA is
// requested but this LibTorch has no CUDA or no device is visible.
torch::Device parse_device(const std::string& name);

// LibTorch defaults to one intra-op thread in some builds: set it explicitly. threads <= 0 means
// all hardware threads. Also applies tune_cpu_process().
void configure_threads(int threads);

// Process settings that LibTorch's CPU kernels need to run at speed (once per process; later
// calls do nothing). Returns what was done, for logs:
//  - OpenBLAS limited to 1 thread (openblas_set_num_threads found with dlsym): its own threads
//    otherwise spin in sched_yield next to LibTorch's OpenMP pool;
//  - glibc malloc keeps large blocks in the heap (no mmap, no trimming), so that the tensors of
//    one forward pass reuse the pages of the previous one instead of page-faulting fresh ones.
std::string tune_cpu_process();

}  // namespace umvs
