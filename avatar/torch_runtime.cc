#include "avatar/torch_runtime.h"

#include <torch/torch.h>

#include <malloc.h>

#include <algorithm>
#include <cstdlib>

#include "core/parallel.h"

namespace headforge {

namespace {
int tensor_threads = 1;
}  // namespace

void ConfigureTorchThreads(int threads) {
  tensor_threads = std::max(1, threads);
  // OpenBLAS (OpenMP) sets OpenMP's count, which is LibTorch's, to its own.
  SetBlasThreads(1);
  at::set_num_threads(1);
}

void KeepFreedTensorMemory() {
  // HEADFORGE_MALLOC=system keeps glibc's defaults, to measure the difference.
  if (const char* m = std::getenv("HEADFORGE_MALLOC"); m && std::string(m) == "system") return;
  // The largest threshold glibc takes (32 MiB on 64-bit); blocks above it
  // still come from and return to the system.
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
}

void UseTensorThreads() {
  SetBlasThreads(tensor_threads);
  at::set_num_threads(tensor_threads);
}

int TensorThreads() { return tensor_threads; }

std::string TorchDescription() {
  std::string text = TORCH_VERSION;
  if (torch::cuda::is_available()) {
    text += " (CUDA, " + std::to_string(torch::cuda::device_count()) + " device(s))";
  } else {
    text += " (CPU)";
  }
  return text;
}

}  // namespace headforge
