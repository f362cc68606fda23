// Triplanes (EG3D, Chan et al. 2022): three axis-aligned feature planes, a
// point's feature the concatenation of its bilinear look-ups on them; and a
// small StyleGAN2-like generator that makes the planes from a latent.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/pimpl.h>

#include <vector>

#include "avatar/nn/mlp.h"
#include "avatar/nn/modulated_conv.h"

namespace headforge::nn {

// Looks `points` [N, 3] (normalised: the planes span [-1, 1] on each axis) up
// on `planes` [3, C, R, R] (the xy, xz and zy planes; image u along the first
// axis named, v along the second), bilinearly with pixel centres at
// (i + 0.5) / R * 2 - 1 and the border value outside -> [N, 3C].
// Differentiable with respect to both. Batched: planes [B, 3, C, R, R] and
// points [B, N, 3] -> [B, N, 3C], each sample's points on its own planes.
torch::Tensor SampleTriplane(const torch::Tensor& planes, const torch::Tensor& points);

struct TriplaneGeneratorOptions {
  int64_t latent_dim = 64;   // the per-frame latent
  int64_t w_dim = 128;       // the mapping network's style
  int64_t channels = 32;     // of the synthesis layers
  int64_t resolution = 64;   // of each plane; a power of two >= 8
  int64_t plane_channels = 16;
  int mapping_layers = 2;
};

// latent [B, latent_dim] -> planes [B, 3, plane_channels, R, R]: a learned
// 4x4 constant, then per resolution 8..R a bilinear 2x upsampling and two
// modulated 3x3 convolutions with LeakyReLU(0.2), then a modulated 1x1
// convolution (no demodulation) to the planes' channels. No per-pixel noise:
// the same latent gives the same planes.
class TriplaneGeneratorImpl : public torch::nn::Module {
 public:
  explicit TriplaneGeneratorImpl(const TriplaneGeneratorOptions& options);
  torch::Tensor forward(const torch::Tensor& latent) { return Synthesize(Map(latent)); }
  // The two halves: the mapping network (latent -> w [B, w_dim]) and the
  // synthesis (w -> planes).
  torch::Tensor Map(const torch::Tensor& latent);
  torch::Tensor Synthesize(const torch::Tensor& w);
  const TriplaneGeneratorOptions& options() const { return options_; }

 private:
  TriplaneGeneratorOptions options_;
  MappingNetwork mapping_{nullptr};
  torch::Tensor constant_;
  torch::nn::ModuleList convs_;
  ModulatedConv2d to_planes_{nullptr};
};
TORCH_MODULE(TriplaneGenerator);

}  // namespace headforge::nn
