// The GAN modules of avatar/nn: discriminator.h and augment.h.
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"
#include "avatar/nn/functional.h"

namespace headforge::nn {

namespace F = torch::nn::functional;

DiscriminatorImpl::DiscriminatorImpl(const DiscriminatorOptions& options) : options_(options) {
  TORCH_CHECK(options.resolution >= 4 && options.in_channels >= 1 && options.channels >= 1,
              "discriminator: bad options");
  from_rgb_ = register_module("from_rgb", torch::nn::Conv2d(torch::nn::Conv2dOptions(options.in_channels,
                                                                                    options.channels, 1)));
  blocks_ = register_module("blocks", torch::nn::ModuleList());
  int64_t channels = options.channels;
  for (int64_t r = options.resolution; r > 4; r /= 2) {
    const int64_t next = std::min(channels * 2, options.max_channels);
    blocks_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(channels, channels, 3).padding(1)));
    blocks_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(channels, next, 3).padding(1)));
    channels = next;
  }
  feature_dim_ = channels;
  flatten_ = register_module("flatten", torch::nn::Linear(channels * 16, channels));
  out_ = register_module("out", torch::nn::Linear(channels, 1));
  if (options.condition_dim > 0)
    embed_ = register_module("embed", Mlp(std::vector<int64_t>{options.condition_dim, channels, channels}));
}

std::vector<torch::Tensor> DiscriminatorImpl::Features(const torch::Tensor& x) {
  std::vector<torch::Tensor> features;
  torch::Tensor h = LeakyRelu(from_rgb_->forward(x));
  for (size_t i = 0; i < blocks_->size(); i += 2) {
    h = LeakyRelu(blocks_[i]->as<torch::nn::Conv2d>()->forward(h));
    h = LeakyRelu(blocks_[i + 1]->as<torch::nn::Conv2d>()->forward(h));
    h = F::avg_pool2d(h, F::AvgPool2dFuncOptions(2).ceil_mode(true));
    features.push_back(h);
  }
  h = F::adaptive_avg_pool2d(h, F::AdaptiveAvgPool2dFuncOptions({4, 4}));
  features.push_back(LeakyRelu(flatten_->forward(h.flatten(1))));
  return features;
}

torch::Tensor DiscriminatorImpl::forward(const torch::Tensor& x, const torch::Tensor& condition) {
  const torch::Tensor h = Features(x).back();  // [B, D]
  torch::Tensor logits = out_->forward(h).squeeze(1);
  if (options_.condition_dim > 0) {
    TORCH_CHECK(condition.defined() && condition.size(1) == options_.condition_dim,
                "discriminator: a conditional discriminator needs its condition");
    logits = logits + (embed_->forward(condition) * h).sum(1) / std::sqrt(double(feature_dim_));
  }
  return logits;
}

torch::Tensor Augment(const torch::Tensor& x, double p, int64_t colour_channels, at::Generator& generator,
                      const AugmentOptions& options) {
  if (p <= 0) return x;
  TORCH_CHECK(colour_channels % 3 == 0 && colour_channels <= x.size(1), "augment: colour channels in threes");
  const int64_t batch = x.size(0);
  const auto cpu = torch::TensorOptions().dtype(torch::kFloat64);
  // Which transforms each sample gets, and their parameters, drawn in a fixed order.
  auto chosen = [&]() { return (torch::rand({batch}, generator, cpu) < p).to(torch::kFloat64); };
  const torch::Tensor use_t = chosen(), use_s = chosen(), use_r = chosen(), use_b = chosen(), use_c = chosen();
  const torch::Tensor t = (torch::rand({batch, 2}, generator, cpu) * 2 - 1) * (2 * options.max_translation);
  const torch::Tensor s = torch::pow(2.0, torch::randn({batch}, generator, cpu) * options.scale_std);
  const torch::Tensor angle = (torch::rand({batch}, generator, cpu) * 2 - 1) * M_PI;
  const torch::Tensor b = torch::randn({batch}, generator, cpu) * options.brightness_std;
  const torch::Tensor c = torch::pow(2.0, torch::randn({batch}, generator, cpu) * options.contrast_std);
  // The sampling grid's affine map (output coordinates -> input), per sample:
  // A = R(theta) / s, offset t; transforms not chosen are the identity.
  const torch::Tensor scale = 1 + use_s * (s - 1);
  const torch::Tensor theta = options.rotate ? angle * use_r : torch::zeros_like(angle);
  const torch::Tensor cos = torch::cos(theta) / scale, sin = torch::sin(theta) / scale;
  const torch::Tensor shift = t * use_t.unsqueeze(1);
  const torch::Tensor affine = torch::stack({torch::stack({cos, -sin, shift.select(1, 0)}, 1),
                                             torch::stack({sin, cos, shift.select(1, 1)}, 1)},
                                            1)
                                   .to(x.options());  // [B, 2, 3]
  const torch::Tensor grid = F::affine_grid(affine, x.sizes(), /*align_corners=*/false);
  torch::Tensor y = F::grid_sample(
      x, grid, F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kReflection).align_corners(false));
  if (colour_channels == 0) return y;
  const torch::Tensor add = (b * use_b).to(x.options()).view({batch, 1, 1, 1});
  const torch::Tensor gain = (1 + use_c * (c - 1)).to(x.options()).view({batch, 1, 1, 1});
  std::vector<torch::Tensor> parts;
  for (int64_t k = 0; k < colour_channels; k += 3) {
    const torch::Tensor rgb = y.narrow(1, k, 3) + add;
    const torch::Tensor mean = rgb.mean({1, 2, 3}, true);
    parts.push_back((rgb - mean) * gain + mean);
  }
  if (colour_channels < y.size(1)) parts.push_back(y.narrow(1, colour_channels, y.size(1) - colour_channels));
  return torch::cat(parts, 1);
}

void AdaController::Observe(const torch::Tensor& real_logits) {
  sign_sum_ += torch::sign(real_logits.detach()).sum().item<double>();
  images_ += real_logits.size(0);
  if (++batches_ < interval_) return;
  last_rt_ = sign_sum_ / double(images_);
  const double step = double(images_) / speed_images_;
  p_ = std::clamp(p_ + (last_rt_ > target_ ? step : -step), 0.0, 1.0);
  sign_sum_ = 0;
  images_ = 0;
  batches_ = 0;
}

void AdaController::Restore(const std::vector<double>& state) {
  if (state.size() < 5) return;
  p_ = state[0];
  sign_sum_ = state[1];
  images_ = int64_t(state[2]);
  batches_ = int(state[3]);
  last_rt_ = state[4];
}

}  // namespace headforge::nn
