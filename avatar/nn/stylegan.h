// A small StyleGAN2 image generator (Karras et al. 2020) and the two pieces
// GaussianStyle (§3.2) fuses into it: a convolutional encoder of a
// multi-channel splat image, and per-block projections that add the
// encoder's feature of a block's resolution into that block's convolution
// outputs.
//
// Generator: mapping z -> w; a learned 4x4 input (or one given); per block
// (4, 8, ..., R px) a 2x bilinear upsampling (not in the first), two
// modulated 3x3 convolutions each followed by per-pixel noise times a learned
// strength, an optional injected feature, a bias-free LeakyReLU(0.2); and a
// tRGB (modulated 1x1, no demodulation) whose outputs are summed over the
// blocks, each upsampled to the next (StyleGAN2's skip architecture).
// Channels per block: channel_base / r clamped to [min, max], thin as
// MobileStyleGAN's where the images are large.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/pimpl.h>

#include <vector>

#include "avatar/nn/mlp.h"
#include "avatar/nn/modulated_conv.h"

namespace headforge::nn {

struct StyleGeneratorOptions {
  int64_t z_dim = 128, w_dim = 128;
  int mapping_layers = 4;
  int64_t resolution = 64;  // the output's side, a power of two >= 8
  int64_t channel_base = 2048, min_channels = 16, max_channels = 128;

  int64_t Channels(int64_t r) const;     // of the block at r px
  int Blocks() const;                    // 4, 8, ..., resolution
  int64_t BlockResolution(int block) const { return int64_t(4) << block; }
};

class StyleGeneratorImpl : public torch::nn::Module {
 public:
  explicit StyleGeneratorImpl(const StyleGeneratorOptions& options);
  const StyleGeneratorOptions& options() const { return options_; }

  torch::Tensor Map(const torch::Tensor& z) { return mapping_->forward(z); }  // [B, z_dim] -> [B, w_dim]

  // w [B, w_dim] -> RGB [B, 3, R', R'] in about [-1, 1]. `input` [B,
  // Channels(4), h, w] replaces the learned 4x4 input (the output is then
  // 2^(blocks-1) times its size); `inject[b]`, where given, is added to both
  // convolutions of block b (its size that block's). Noise: drawn from
  // `noise` when given, else the fixed per-layer noise (inference,
  // deterministic), which a non-square or resized input leaves out.
  torch::Tensor Synthesize(const torch::Tensor& w, const std::vector<torch::Tensor>& inject = {},
                           const torch::Tensor& input = {}, at::Generator* noise = nullptr);
  torch::Tensor constant() const { return constant_; }

 private:
  StyleGeneratorOptions options_;
  MappingNetwork mapping_{nullptr};
  torch::Tensor constant_;
  torch::nn::ModuleList convs_, to_rgb_;
  std::vector<torch::Tensor> noise_strength_, fixed_noise_;
};
TORCH_MODULE(StyleGenerator);

// An image [B, in, R, R] -> its features at R, R/2, ..., 4 px, with the
// generator's channel counts (Channels(r)): a 1x1 convolution in, then per
// level two 3x3 convolutions with LeakyReLU(0.2) and a 2x average pooling.
// Returned coarsest first: [0] is 4 px, [k] is 4 * 2^k px.
class ConvEncoderImpl : public torch::nn::Module {
 public:
  ConvEncoderImpl(int64_t in_channels, const StyleGeneratorOptions& generator);
  std::vector<torch::Tensor> forward(const torch::Tensor& x);

 private:
  StyleGeneratorOptions generator_;
  torch::nn::Conv2d from_input_{nullptr};
  torch::nn::ModuleList convs_;
};
TORCH_MODULE(ConvEncoder);

// Two 3x3 convolutions (LeakyReLU between) from a feature to what a block
// adds to its convolutions; the second starts at zero, so that a fresh
// projection leaves the generator as it was.
class ProjectionImpl : public torch::nn::Module {
 public:
  ProjectionImpl(int64_t in_channels, int64_t out_channels);
  torch::Tensor forward(const torch::Tensor& x);

  torch::nn::Conv2d first{nullptr}, second{nullptr};
};
TORCH_MODULE(Projection);

}  // namespace headforge::nn
