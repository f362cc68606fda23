#include "avatar/train/tensor_safetensors.h"

#include <torch/torch.h>

#include <cstring>
#include <map>

namespace headforge {

namespace {

const std::map<std::string, torch::ScalarType>& Types() {
  static const std::map<std::string, torch::ScalarType> types = {{"F32", torch::kFloat32}, {"F64", torch::kFloat64},
                                                                 {"I64", torch::kInt64},   {"I32", torch::kInt32},
                                                                 {"U8", torch::kUInt8}};
  return types;
}

}  // namespace

SafeTensor ToSafeTensor(const std::string& name, const torch::Tensor& tensor) {
  const torch::Tensor t = tensor.detach().cpu().contiguous();
  SafeTensor out;
  out.name = name;
  out.shape.assign(t.sizes().begin(), t.sizes().end());
  out.dtype.clear();
  for (const auto& [dtype, type] : Types())
    if (type == t.scalar_type()) out.dtype = dtype;
  TORCH_CHECK(!out.dtype.empty(), "safetensors: ", name, " has a type the writer does not take");
  const auto* bytes = static_cast<const uint8_t*>(t.data_ptr());
  out.bytes.assign(bytes, bytes + t.nbytes());
  return out;
}

bool FromSafeTensor(const SafeTensor& s, torch::Tensor* tensor) {
  const auto it = Types().find(s.dtype);
  if (it == Types().end()) return false;
  *tensor = torch::empty(s.shape, torch::TensorOptions().dtype(it->second));
  if (s.bytes.size() != tensor->nbytes()) return false;
  if (!s.bytes.empty()) std::memcpy(tensor->data_ptr(), s.bytes.data(), s.bytes.size());
  return true;
}

}  // namespace headforge
