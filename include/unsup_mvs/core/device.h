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
//    one forward pass reuse the pages of the previous one instead of page-faulting fresh ones,
//    in one arena (per-thread arenas would each keep their own peak).
std::string tune_cpu_process();

// Threads that an at::parallel_for in this library really runs on (with the current
// torch::get_num_threads()): 1 when the library was compiled without OpenMP although LibTorch's
// backend is OpenMP. For diagnostics (umvs bench) and tests.
int parallel_loop_threads();

}  // namespace umvs
