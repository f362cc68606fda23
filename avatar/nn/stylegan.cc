// The StyleGAN2 generator, the splat-image encoder and the projections of stylegan.h.
#include <torch/torch.h>

#include <algorithm>

#include "avatar/nn/functional.h"
#include "avatar/nn/stylegan.h"

namespace headforge::nn {

namespace F = torch::nn::functional;

int64_t StyleGeneratorOptions::Channels(int64_t r) const {
  return std::clamp(channel_base / std::max<int64_t>(r, 1), min_channels, max_channels);
}

int StyleGeneratorOptions::Blocks() const {
  int blocks = 0;
  for (int64_t r = 4; r <= resolution; r *= 2) ++blocks;
  return blocks;
}

StyleGeneratorImpl::StyleGeneratorImpl(const StyleGeneratorOptions& options) : options_(options) {
  TORCH_CHECK(options.resolution >= 8 && (options.resolution & (options.resolution - 1)) == 0,
              "style generator: the resolution must be a power of two of at least 8");
  mapping_ = register_module("mapping", MappingNetwork(options.z_dim, options.w_dim, options.mapping_layers));
  constant_ = register_parameter("constant", torch::randn({1, options.Channels(4), 4, 4}));
  convs_ = register_module("convs", torch::nn::ModuleList());
  to_rgb_ = register_module("to_rgb", torch::nn::ModuleList());
  // The fixed noise comes from its own seed: a loaded generator has the same.
  auto noise_generator = at::detail::createCPUGenerator(0x5EED);
  int64_t in = options.Channels(4);
  for (int block = 0; block < options.Blocks(); ++block) {
    const int64_t r = options.BlockResolution(block), out = options.Channels(r);
    for (int k = 0; k < 2; ++k) {
      convs_->push_back(ModulatedConv2d(k == 0 ? in : out, out, 3, options.w_dim));
      const std::string index = std::to_string(2 * block + k);
      noise_strength_.push_back(register_parameter("noise_strength" + index, torch::zeros({1})));
      fixed_noise_.push_back(torch::randn({1, 1, r, r}, noise_generator));
    }
    to_rgb_->push_back(ModulatedConv2d(out, 3, 1, options.w_dim, /*demodulate=*/false));
    in = out;
  }
}

torch::Tensor StyleGeneratorImpl::Synthesize(const torch::Tensor& w, const std::vector<torch::Tensor>& inject,
                                             const torch::Tensor& input, at::Generator* noise) {
  const int64_t batch = w.size(0);
  torch::Tensor x = input.defined() ? input : constant_.expand({batch, -1, -1, -1});
  TORCH_CHECK(x.size(1) == options_.Channels(4), "style generator: the input needs ", options_.Channels(4),
              " channels, not ", x.size(1));
  const bool native = x.size(2) == 4 && x.size(3) == 4;
  torch::Tensor rgb;
  for (int block = 0; block < options_.Blocks(); ++block) {
    if (block > 0) x = ResizeBilinear(x, 2 * x.size(2), 2 * x.size(3));
    for (int k = 0; k < 2; ++k) {
      const size_t i = size_t(2 * block + k);
      x = convs_[i]->as<ModulatedConv2d>()->forward(x, w);
      if (noise != nullptr) {
        x = x + noise_strength_[i] * torch::randn({batch, 1, x.size(2), x.size(3)}, *noise).to(x.options());
      } else if (native) {
        x = x + noise_strength_[i] * fixed_noise_[i].to(x.options());
      }
      if (size_t(block) < inject.size() && inject[size_t(block)].defined()) x = x + inject[size_t(block)];
      x = LeakyRelu(x);
    }
    const torch::Tensor y = to_rgb_[size_t(block)]->as<ModulatedConv2d>()->forward(x, w);
    rgb = rgb.defined() ? ResizeBilinear(rgb, y.size(2), y.size(3)) + y : y;
  }
  return rgb;
}

ConvEncoderImpl::ConvEncoderImpl(int64_t in_channels, const StyleGeneratorOptions& generator) : generator_(generator) {
  from_input_ = register_module(
      "from_input", torch::nn::Conv2d(torch::nn::Conv2dOptions(in_channels, generator.Channels(generator.resolution), 1)));
  convs_ = register_module("convs", torch::nn::ModuleList());
  for (int64_t r = generator.resolution; r >= 4; r /= 2) {
    const int64_t c = generator.Channels(r);
    convs_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(c, c, 3).padding(1)));
    if (r > 4) convs_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(c, generator.Channels(r / 2), 3).padding(1)));
  }
}

std::vector<torch::Tensor> ConvEncoderImpl::forward(const torch::Tensor& x) {
  std::vector<torch::Tensor> features;
  torch::Tensor h = LeakyRelu(from_input_->forward(x));
  size_t next = 0;
  for (int64_t r = generator_.resolution; r >= 4; r /= 2) {
    h = LeakyRelu(convs_[next++]->as<torch::nn::Conv2d>()->forward(h));
    features.push_back(h);
    if (r == 4) break;
    h = LeakyRelu(convs_[next++]->as<torch::nn::Conv2d>()->forward(h));
    h = F::avg_pool2d(h, F::AvgPool2dFuncOptions(2));
  }
  std::reverse(features.begin(), features.end());
  return features;
}

ProjectionImpl::ProjectionImpl(int64_t in_channels, int64_t out_channels) {
  first = register_module("first", torch::nn::Conv2d(torch::nn::Conv2dOptions(in_channels, out_channels, 3).padding(1)));
  second =
      register_module("second", torch::nn::Conv2d(torch::nn::Conv2dOptions(out_channels, out_channels, 3).padding(1)));
  torch::NoGradGuard no_grad;
  second->weight.zero_();
  second->bias.zero_();
}

torch::Tensor ProjectionImpl::forward(const torch::Tensor& x) { return second->forward(LeakyRelu(first->forward(x))); }

}  // namespace headforge::nn
