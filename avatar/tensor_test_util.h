// What the avatar tests' files share about tensors.
#pragma once

#include <torch/torch.h>

namespace headforge {

// Double precision, for gradient checks against finite differences.
inline const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

}  // namespace headforge
