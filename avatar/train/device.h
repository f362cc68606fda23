// The device a tensor job runs on, from its --device option.
#pragma once

#include <torch/types.h>

#include <string>

#include "core/status.h"

namespace headforge {

// "cpu", "cuda" or "cuda:N" into `device`; `who` names the command in the
// errors (not a device, not one with kernels, no CUDA device in this build).
Status ParseDevice(const std::string& who, const std::string& name, torch::Device* device);

}  // namespace headforge
