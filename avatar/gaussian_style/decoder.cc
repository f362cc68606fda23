// The stage-3 decoder of decoder.h: its module, the square canvas it draws
// on, and the generator's weight files.
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "avatar/gaussian_style/decoder.h"
#include "avatar/train/tensor_safetensors.h"
#include "core/safetensors.h"

namespace headforge {

nlohmann::json ToJson(const StyleDecoderOptions& o) {
  const nn::StyleGeneratorOptions& g = o.generator;
  return {{"feature_channels", o.feature_channels}, {"projected_blocks", o.projected_blocks},
          {"z_dim", g.z_dim}, {"w_dim", g.w_dim}, {"mapping_layers", g.mapping_layers},
          {"resolution", g.resolution}, {"channel_base", g.channel_base}, {"min_channels", g.min_channels},
          {"max_channels", g.max_channels}};
}

StyleDecoderOptions StyleDecoderOptionsFromJson(const nlohmann::json& j) {
  StyleDecoderOptions o;
  o.feature_channels = j.at("feature_channels").get<int64_t>();
  o.projected_blocks = j.at("projected_blocks").get<int>();
  nn::StyleGeneratorOptions& g = o.generator;
  g.z_dim = j.at("z_dim").get<int64_t>();
  g.w_dim = j.at("w_dim").get<int64_t>();
  g.mapping_layers = j.at("mapping_layers").get<int>();
  g.resolution = j.at("resolution").get<int64_t>();
  g.channel_base = j.at("channel_base").get<int64_t>();
  g.min_channels = j.at("min_channels").get<int64_t>();
  g.max_channels = j.at("max_channels").get<int64_t>();
  return o;
}

StyleDecoderImpl::StyleDecoderImpl(const StyleDecoderOptions& options) : options_(options) {
  const nn::StyleGeneratorOptions& g = options.generator;
  generator = register_module("generator", nn::StyleGenerator(g));
  encoder = register_module("encoder", nn::ConvEncoder(options.feature_channels, g));
  input_projection = register_module("input_projection", nn::Projection(g.Channels(4), g.Channels(4)));
  projections = register_module("projections", torch::nn::ModuleList());
  const int projected = std::min(options.projected_blocks, g.Blocks());
  for (int b = 0; b < projected; ++b) {
    const int64_t c = g.Channels(g.BlockResolution(b));
    projections->push_back(nn::Projection(c, c));
  }
  w = register_parameter("w", torch::zeros({1, g.w_dim}));
}

torch::Tensor StyleDecoderImpl::forward(const torch::Tensor& splat) {
  const int64_t batch = splat.size(0);
  const std::vector<torch::Tensor> features = encoder->forward(splat);  // 4 px first
  std::vector<torch::Tensor> inject;
  for (size_t b = 0; b < projections->size(); ++b)
    inject.push_back(projections[b]->as<nn::Projection>()->forward(features[b]));
  const torch::Tensor input =
      generator->constant().expand({batch, -1, -1, -1}) + input_projection->forward(features.front());
  return (generator->Synthesize(w.expand({batch, -1}), inject, input) + 1) * 0.5;
}

torch::Tensor StyleDecoderImpl::Generate(const torch::Tensor& latent, at::Generator* noise) {
  return (generator->Synthesize(latent, {}, {}, noise) + 1) * 0.5;
}

std::vector<torch::Tensor> StyleDecoderImpl::FusionParameters() {
  std::vector<torch::Tensor> out = encoder->parameters();
  for (const torch::Tensor& t : input_projection->parameters()) out.push_back(t);
  for (const torch::Tensor& t : projections->parameters()) out.push_back(t);
  return out;
}

Status LoadGeneratorWeights(const fs::path& path, nn::StyleGeneratorImpl* generator) {
  SafeTensorsFile file;
  HF_RETURN_IF_ERROR(ReadSafetensors(path, &file));
  torch::NoGradGuard no_grad;
  for (auto& item : generator->named_parameters()) {
    const SafeTensor* s = file.Find(item.key());
    torch::Tensor value;
    if (s == nullptr || s->dtype != "F32" || !FromSafeTensor(*s, &value) ||
        !value.sizes().equals(item.value().sizes()))
      return Status::DataError(path.string() + ": no F32 tensor " + item.key() + " of shape " +
                               c10::str(item.value().sizes()) +
                               " (the generator's layout: docs/avatar.md, \"Generator weights\"; the generator's "
                               "options --decoder-resolution and the channel counts must match the file's)");
    item.value().copy_(value.to(item.value().device()));
  }
  return Status::Ok();
}

Status SaveGeneratorWeights(const nn::StyleGeneratorImpl& generator, const fs::path& path) {
  SafeTensorsFile file;
  file.metadata["format"] = "pt";
  file.metadata["model"] = "headforge-style-generator";
  for (const auto& item : generator.named_parameters())
    file.tensors.push_back(ToSafeTensor(item.key(), item.value()));
  return WriteSafetensors(path, file);
}

}  // namespace headforge
