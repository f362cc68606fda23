#include "avatar/train/tensor_safetensors.h"

#include <torch/torch.h>

#include <cstring>
#include <map>

namespace headforge {

SafeTensor ToSafeTensor(const std::string& name, const torch::Tensor& tensor) {
  const torch::Tensor t = tensor.detach().cpu().contiguous();
  SafeTensor out;
  out.name = name;
  out.shape.assign(t.sizes().begin(), t.sizes().end());
  if (t.scalar_type() == torch::kFloat32) {
    out.dtype = "F32";
  } else if (t.scalar_type() == torch::kInt64) {
    out.dtype = "I64";
  } else if (t.scalar_type() == torch::kFloat64) {
    out.dtype = "F64";
  } else {
    TORCH_CHECK(false, "weights export: ", name, " has a type the writer does not take");
  }
  const auto* bytes = static_cast<const uint8_t*>(t.data_ptr());
  out.bytes.assign(bytes, bytes + t.nbytes());
  return out;
}

bool FromSafeTensor(const SafeTensor& s, torch::Tensor* tensor) {
  const std::map<std::string, torch::ScalarType> types = {
      {"F32", torch::kFloat32}, {"F64", torch::kFloat64}, {"I64", torch::kInt64}};
  const auto it = types.find(s.dtype);
  if (it == types.end()) return false;
  *tensor = torch::empty(s.shape, torch::TensorOptions().dtype(it->second));
  if (s.bytes.size() != tensor->nbytes()) return false;
  if (!s.bytes.empty()) std::memcpy(tensor->data_ptr(), s.bytes.data(), s.bytes.size());
  return true;
}

}  // namespace headforge
