#include "avatar/torch_runtime.h"

#include <torch/torch.h>

#include <algorithm>

namespace headforge {

void ConfigureTorchThreads(int threads) {
  at::set_num_threads(std::max(1, threads));
}

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
