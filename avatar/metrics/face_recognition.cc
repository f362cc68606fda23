#include "avatar/metrics/face_recognition.h"

#include <torch/torch.h>


namespace headforge {

namespace F = torch::nn::functional;

Status FaceRecognitionNetImpl::Create(const std::map<std::string, torch::Tensor>& weights,
                                      std::shared_ptr<FaceRecognitionNetImpl>* net) {
  auto out = std::make_shared<FaceRecognitionNetImpl>();
  auto get = [&](const std::string& name, std::vector<int64_t> shape, torch::Tensor* t) {
    const auto it = weights.find(name);
    if (it == weights.end()) return Status::DataError("face recognition: no weights '" + name + "'");
    if (it->second.sizes() != torch::IntArrayRef(shape))
      return Status::DataError("face recognition: '" + name + "' has the wrong shape");
    *t = it->second;
    return Status::Ok();
  };
  // A convolution's filters are stored [k, k, in, out] (TensorFlow's layout).
  auto conv = [&](const std::string& prefix, int64_t k, int64_t in, int64_t channels) {
    Conv c;
    HF_RETURN_IF_ERROR(get(prefix + "/conv/filters", {k, k, in, channels}, &c.filters));
    HF_RETURN_IF_ERROR(get(prefix + "/conv/bias", {channels}, &c.bias));
    HF_RETURN_IF_ERROR(get(prefix + "/scale/weights", {channels}, &c.scale));
    HF_RETURN_IF_ERROR(get(prefix + "/scale/biases", {channels}, &c.offset));
    c.filters = c.filters.permute({3, 2, 0, 1}).contiguous();
    out->convs_[prefix] = c;
    return Status::Ok();
  };
  HF_RETURN_IF_ERROR(conv("conv32_down", 7, 3, 32));
  struct Block {
    const char* name;
    int64_t in, channels;
  };
  const Block blocks[] = {{"conv32_1", 32, 32},      {"conv32_2", 32, 32},      {"conv32_3", 32, 32},
                          {"conv64_down", 32, 64},   {"conv64_1", 64, 64},      {"conv64_2", 64, 64},
                          {"conv64_3", 64, 64},      {"conv128_down", 64, 128}, {"conv128_1", 128, 128},
                          {"conv128_2", 128, 128},   {"conv256_down", 128, 256}, {"conv256_1", 256, 256},
                          {"conv256_2", 256, 256},   {"conv256_down_out", 256, 256}};
  for (const Block& b : blocks) {
    HF_RETURN_IF_ERROR(conv(std::string(b.name) + "/conv1", 3, b.in, b.channels));
    HF_RETURN_IF_ERROR(conv(std::string(b.name) + "/conv2", 3, b.channels, b.channels));
  }
  HF_RETURN_IF_ERROR(get("fc", {256, 128}, &out->fc_));
  *net = out;
  return Status::Ok();
}

torch::Tensor FaceRecognitionNetImpl::Apply(const Conv& c, const torch::Tensor& x, int stride, bool relu) const {
  // TensorFlow's "same" for a 3x3 of stride 1 pads one on each side; its
  // "valid" (the strided ones) none.
  const int64_t k = c.filters.size(2), padding = stride == 1 ? k / 2 : 0;
  torch::Tensor y = F::conv2d(x, c.filters.to(x.device()), F::Conv2dFuncOptions().stride(stride).padding(padding));
  auto channel = [&](const torch::Tensor& v) { return v.to(x.device()).view({1, -1, 1, 1}); };
  y = (y + channel(c.bias)) * channel(c.scale) + channel(c.offset);
  return relu ? torch::relu(y) : y;
}

torch::Tensor FaceRecognitionNetImpl::Residual(const std::string& block, const torch::Tensor& x) const {
  torch::Tensor y = Apply(convs_.at(block + "/conv1"), x, 1, true);
  y = Apply(convs_.at(block + "/conv2"), y, 1, false);
  return torch::relu(y + x);
}

torch::Tensor FaceRecognitionNetImpl::ResidualDown(const std::string& block, const torch::Tensor& x) const {
  torch::Tensor y = Apply(convs_.at(block + "/conv1"), x, 2, true);
  y = Apply(convs_.at(block + "/conv2"), y, 1, false);
  torch::Tensor shortcut = F::avg_pool2d(x, F::AvgPool2dFuncOptions(2).stride(2));
  if (shortcut.size(2) != y.size(2) || shortcut.size(3) != y.size(3))
    y = F::pad(y, F::PadFuncOptions({0, shortcut.size(3) - y.size(3), 0, shortcut.size(2) - y.size(2)}));
  if (shortcut.size(1) != y.size(1))
    shortcut = F::pad(shortcut, F::PadFuncOptions({0, 0, 0, 0, 0, y.size(1) - shortcut.size(1)}));
  return torch::relu(y + shortcut);
}

torch::Tensor FaceRecognitionNetImpl::forward(const torch::Tensor& crops) {
  TORCH_CHECK(crops.dim() == 4 && crops.size(1) == 3 && crops.size(2) == 150 && crops.size(3) == 150,
              "face recognition: crops must be [B, 3, 150, 150]");
  const torch::Tensor mean = torch::tensor({122.782, 117.001, 104.298}, crops.options()).view({1, 3, 1, 1});
  torch::Tensor x = (crops - mean) / 255;
  x = Apply(convs_.at("conv32_down"), x, 2, true);
  x = F::max_pool2d(x, F::MaxPool2dFuncOptions(3).stride(2));
  for (const char* b : {"conv32_1", "conv32_2", "conv32_3"}) x = Residual(b, x);
  x = ResidualDown("conv64_down", x);
  for (const char* b : {"conv64_1", "conv64_2", "conv64_3"}) x = Residual(b, x);
  x = ResidualDown("conv128_down", x);
  for (const char* b : {"conv128_1", "conv128_2"}) x = Residual(b, x);
  x = ResidualDown("conv256_down", x);
  for (const char* b : {"conv256_1", "conv256_2"}) x = Residual(b, x);
  x = ResidualDown("conv256_down_out", x);
  return x.mean({2, 3}).matmul(fc_.to(x.device()));
}

}  // namespace headforge
