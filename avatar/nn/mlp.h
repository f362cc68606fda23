// Fully connected networks: a plain MLP and StyleGAN's mapping network
// (latent z -> style w). Modules as FooImpl + TORCH_MODULE(Foo); [B, ...]
// batches first.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/sequential.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/pimpl.h>

#include <vector>

namespace headforge::nn {

// Linear layers with LeakyReLU(0.2) between them (none after the last).
// `widths` = {in, hidden..., out}. `zero_last` starts the last layer at zero,
// so that a network predicting residuals starts as the identity.
class MlpImpl : public torch::nn::Module {
 public:
  MlpImpl(const std::vector<int64_t>& widths, bool zero_last = false);
  torch::Tensor forward(const torch::Tensor& x);  // [..., in] -> [..., out]

 private:
  std::vector<torch::nn::Linear> layers_;
};
TORCH_MODULE(Mlp);

// z [B, z_dim] -> w [B, w_dim]: z normalised to unit RMS, then `layers`
// linear layers of width w_dim with LeakyReLU(0.2). (StyleGAN's equalised
// learning rate is left out: Adam's per-weight steps make it matter less.)
class MappingNetworkImpl : public torch::nn::Module {
 public:
  MappingNetworkImpl(int64_t z_dim, int64_t w_dim, int layers);
  torch::Tensor forward(const torch::Tensor& z);

 private:
  Mlp mlp_{nullptr};
};
TORCH_MODULE(MappingNetwork);

}  // namespace headforge::nn
