// Between LibTorch tensors and core/safetensors.h's entries (F32, F64, I64,
// I32 and U8), for the weight files the avatars write and read and the
// training packs.
#pragma once

#include <torch/types.h>

#include <string>

#include "core/safetensors.h"

namespace headforge {

// The tensor's bytes under `name` (moved to the CPU, contiguous); throws
// c10::Error for a type the format here does not take.
SafeTensor ToSafeTensor(const std::string& name, const torch::Tensor& tensor);
// False for a type it does not read.
bool FromSafeTensor(const SafeTensor& s, torch::Tensor* tensor);

}  // namespace headforge
