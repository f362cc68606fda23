// The gaussian-style avatar's stage 3 (GaussianStyle §3.2): the splatted
// 32-channel feature image is encoded, and the encoder's features fused
// into the convolutions of a StyleGAN2 generator's first blocks (4..64 px),
// whose output is the avatar's image. The generator is the subject's own
// (no pretrained FFHQ weights here): trained unconditionally on the
// training frames, inverted onto the frames of the most extreme head poses
// and fine-tuned on them (PTI), then frozen while the encoder, the
// projections and the Gaussians' networks learn to drive it.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/pimpl.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "avatar/nn/stylegan.h"
#include "avatar/train/view_camera.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct StyleDecoderOptions {
  int64_t feature_channels = 32;  // of the splat image
  nn::StyleGeneratorOptions generator;
  int projected_blocks = 5;       // blocks 4, 8, ... px that take the encoder's feature (the paper: 5, up to 64 px)
};
nlohmann::json ToJson(const StyleDecoderOptions& options);
StyleDecoderOptions StyleDecoderOptionsFromJson(const nlohmann::json& j);

class StyleDecoderImpl : public torch::nn::Module {
 public:
  explicit StyleDecoderImpl(const StyleDecoderOptions& options);
  const StyleDecoderOptions& options() const { return options_; }

  // splat [B, C, S, S] (S the generator's resolution) -> RGB [B, 3, S, S],
  // about [0, 1]: the generator at the fixed w, its 4x4 input the learned
  // constant plus the encoder's coarsest feature, blocks up to
  // projected_blocks taking theirs.
  torch::Tensor forward(const torch::Tensor& splat);
  // The generator alone at w [B, w_dim] -> [B, 3, S, S] in about [0, 1];
  // per-pixel noise from `noise` when given.
  torch::Tensor Generate(const torch::Tensor& w, at::Generator* noise = nullptr);

  // Stage 3's trained parts: the encoder, the input projection and the block projections.
  std::vector<torch::Tensor> FusionParameters();

  nn::StyleGenerator generator{nullptr};
  nn::ConvEncoder encoder{nullptr};
  nn::Projection input_projection{nullptr};
  torch::nn::ModuleList projections;
  torch::Tensor w;  // [1, w_dim]: the latent every frame is decoded at (PTI's)

 private:
  StyleDecoderOptions options_;
};
TORCH_MODULE(StyleDecoder);

// Loads a generator's weights (`--decoder-init`): a .safetensors file with
// one F32 tensor per parameter of `generator`, under its parameter name and
// shape (docs/avatar.md, "Generator weights"). A clear error names the first
// tensor missing or of another shape.
Status LoadGeneratorWeights(const fs::path& path, nn::StyleGeneratorImpl* generator);
// The generator's parameters in that layout.
Status SaveGeneratorWeights(const nn::StyleGeneratorImpl& generator, const fs::path& path);

}  // namespace headforge
