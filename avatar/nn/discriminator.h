// A convolutional GAN discriminator with a conditioning vector (the camera,
// for the gan-avatar model) joined by projection (Miyato and Koyama 2018,
// "cGANs with Projection Discriminator"; StyleGAN2-ADA's conditional
// discriminator works the same way): logit = out(h) + <embed(c), h> / sqrt(D)
// for the image's feature h. Extra image channels (a UV map, a second
// resolution of the image) are just more input channels.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/pimpl.h>

#include <vector>

#include "avatar/nn/mlp.h"

namespace headforge::nn {

struct DiscriminatorOptions {
  int64_t in_channels = 3;
  int64_t resolution = 64;      // the input's longer side; blocks halve it down to 4
  int64_t channels = 32;        // of the first block, doubling per block up to max_channels
  int64_t max_channels = 256;
  int64_t condition_dim = 0;    // 0: unconditional
};

class DiscriminatorImpl : public torch::nn::Module {
 public:
  explicit DiscriminatorImpl(const DiscriminatorOptions& options);
  // x [B, in, H, W] (H, W at most the resolution), condition [B, condition_dim]
  // (undefined when unconditional) -> logits [B].
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& condition = {});
  // Each block's activations and the final feature h, for feature matching.
  std::vector<torch::Tensor> Features(const torch::Tensor& x);

 private:
  DiscriminatorOptions options_;
  torch::nn::Conv2d from_rgb_{nullptr};
  torch::nn::ModuleList blocks_;  // pairs of 3x3 convolutions, each pair then 2x average pooling
  torch::nn::Linear flatten_{nullptr}, out_{nullptr};
  Mlp embed_{nullptr};
  int64_t feature_dim_ = 0;
};
TORCH_MODULE(Discriminator);

}  // namespace headforge::nn
