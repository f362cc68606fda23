#include "avatar/torch_runtime.h"

#include <torch/torch.h>

#include <algorithm>

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
