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
  // HEADFORGE_MALLOC=system keeps glibc's defaults and =threshold only raises
  // the mmap threshold (what this did before), to measure the difference.
  const char* m = std::getenv("HEADFORGE_MALLOC");
  const std::string mode = m ? m : "";
  if (mode == "system") return;
  // Blocks above the mmap threshold (at most 32 MiB on 64-bit) are mapped
  // afresh for each allocation and every page faults on first touch; a
  // training step allocates and frees the same large blocks many times (the
  // deformation's attention weights pass 32 MiB at about 38 000 Gaussians).
  // Without mmap they come from the heap, which keeps up to 1 GiB freed.
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  if (mode != "threshold") mallopt(M_MMAP_MAX, 0);
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
