// Posing, rendering, scoring, saving and loading a gaussian-style avatar.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/metrics/image_metrics.h"
#include "avatar/model_table.h"
#include "avatar/nn/functional.h"
#include "avatar/splat/splat_ops.h"
#include "avatar/train/checkpoint.h"
#include "avatar/train/tensor_safetensors.h"
#include "core/json_io.h"
#include "core/safetensors.h"

namespace headforge {

PosedGaussians GaussianStyleAvatar::Pose(const AvatarDataset& data, const torch::Tensor& condition, int64_t latent,
                                         bool deform_now, const torch::Tensor& vertices) {
  const torch::Device device = gaussians.params.means.device();
  if (!model->options().mesh_riding)
    return model->Pose(gaussians, condition.to(device), latent, nullptr, nullptr, deform_now);
  TriangleFrames mesh;
  {
    torch::NoGradGuard no_grad;  // the mesh is data, not trained
    const int64_t e = model->options().expressions;
    const torch::Tensor v = vertices.defined() ? vertices : data.Vertices(condition.slice(0, 0, e));
    mesh = ComputeTriangleFrames(v.to(device), data.triangles.to(device), gaussians.binding);
  }
  return model->Pose(gaussians, condition.to(device), latent, &mesh, &neutral, deform_now);
}

PosedGaussians GaussianStyleAvatar::Pose(const AvatarDataset& data, const AvatarView& view, int64_t latent,
                                         bool deform_now) {
  return Pose(data, view.condition, latent, deform_now,
              model->options().mesh_riding ? data.Vertices(view) : torch::Tensor());
}

torch::Tensor RenderRgb(const PosedGaussians& posed, const SplatCamera& camera, const torch::Tensor& background) {
  return RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities, posed.features.slice(1, 0, 3),
                         background, camera)
      .image;
}

torch::Tensor DecodeRender(StyleDecoderImpl& decoder, const PosedGaussians& posed, const SplatCamera& camera) {
  const int side = int(decoder.options().generator.resolution);
  const SquareCanvas canvas = MakeSquareCanvas(camera, side);
  torch::Tensor background = torch::zeros({posed.features.size(1)}, posed.features.options());
  background.slice(0, 0, 3).fill_(kDecoderBackground);
  const torch::Tensor splat = RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities,
                                              posed.features, background, canvas.camera)
                                  .image;
  torch::Tensor image = decoder.forward(splat.unsqueeze(0))
                            .slice(2, canvas.y0, canvas.y0 + canvas.height)
                            .slice(3, canvas.x0, canvas.x0 + canvas.width);
  if (canvas.width != camera.width || canvas.height != camera.height)
    image = nn::ResizeBilinear(image, camera.height, camera.width);
  return image[0];
}

torch::Tensor GaussianStyleAvatar::Draw(const PosedGaussians& posed, const SplatCamera& camera,
                                        const torch::Tensor& background) {
  return decoder ? DecodeRender(*decoder, posed, camera) : RenderRgb(posed, camera, background);
}


namespace {

nlohmann::json OptionsJson(const GaussianStyleOptions& o) {
  return {{"feature_channels", o.feature_channels},
          {"latent_dim", o.triplane.latent_dim},
          {"w_dim", o.triplane.w_dim},
          {"generator_channels", o.triplane.channels},
          {"triplane_resolution", o.triplane.resolution},
          {"plane_channels", o.triplane.plane_channels},
          {"mapping_layers", o.triplane.mapping_layers},
          {"token_dim", o.token_dim},
          {"heads", o.heads},
          {"blocks", o.blocks},
          {"ffn_hidden", o.ffn_hidden},
          {"deform_hidden", o.deform_hidden},
          {"expressions", o.expressions},
          {"mesh_riding", o.mesh_riding},
          {"box_half_size", o.box_half_size}};
}

GaussianStyleOptions OptionsFromJson(const nlohmann::json& j) {
  GaussianStyleOptions o;
  o.feature_channels = j.at("feature_channels").get<int64_t>();
  o.triplane.latent_dim = j.at("latent_dim").get<int64_t>();
  o.triplane.w_dim = j.at("w_dim").get<int64_t>();
  o.triplane.channels = j.at("generator_channels").get<int64_t>();
  o.triplane.resolution = j.at("triplane_resolution").get<int64_t>();
  o.triplane.plane_channels = j.at("plane_channels").get<int64_t>();
  o.triplane.mapping_layers = j.at("mapping_layers").get<int>();
  o.token_dim = j.at("token_dim").get<int64_t>();
  o.heads = j.at("heads").get<int64_t>();
  o.blocks = j.at("blocks").get<int>();
  o.ffn_hidden = j.at("ffn_hidden").get<int64_t>();
  o.deform_hidden = j.at("deform_hidden").get<int64_t>();
  o.expressions = j.at("expressions").get<int64_t>();
  o.mesh_riding = j.at("mesh_riding").get<bool>();
  o.box_half_size = j.at("box_half_size").get<double>();
  return o;
}

const char* const kGaussianNames[] = {"means", "quats", "log_scales", "opacity_logits", "features"};

// The avatar's tensors under the names model.pt and weights.safetensors
// share: "gaussians.<name>" and "model.<parameter path>".
std::vector<std::pair<std::string, torch::Tensor>> NamedTensors(const GaussianStyleAvatar& avatar) {
  std::vector<std::pair<std::string, torch::Tensor>> out;
  GaussianParams p = avatar.gaussians.params;
  const auto params = p.All();
  for (size_t i = 0; i < params.size(); ++i) out.emplace_back(std::string("gaussians.") + kGaussianNames[i], *params[i]);
  if (avatar.gaussians.binding.defined()) out.emplace_back("gaussians.binding", avatar.gaussians.binding);
  for (const auto& item : avatar.model->named_parameters()) out.emplace_back("model." + item.key(), item.value());
  if (avatar.decoder)
    for (const auto& item : avatar.decoder->named_parameters()) out.emplace_back("decoder." + item.key(), item.value());
  if (avatar.pose_corrections.defined()) out.emplace_back("pose_corrections", avatar.pose_corrections);
  return out;
}

}  // namespace

nlohmann::json ConfigJson(const GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data) {
  TrainOptions recorded = options;
  recorded.data = options.DataFor(kGaussianStyle);  // the masks it trained on, as render and export read them
  nlohmann::json config = {{"version", 1},
          {"model", kGaussianStyle.name},
          {"architecture", OptionsJson(avatar.model->options())},
          {"frames", data.num_frames},
          {"deform", avatar.deform},
          {"width", data.width},
          {"height", data.height},
          {"gaussians", avatar.gaussians.params.size()},
          {"expression_names", data.expression_names},
          {"options", ToJson(recorded)}};
  if (avatar.decoder) config["decoder"] = ToJson(avatar.decoder->options());
  return config;
}

Status SaveAvatar(const GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data,
                  const fs::path& dir) {
  Checkpoint c;
  for (const auto& [name, tensor] : NamedTensors(avatar)) c.Put(name, tensor);
  HF_RETURN_IF_ERROR(c.Save(dir / "model.pt"));
  return WriteJsonAtomic(dir / "config.json", ConfigJson(avatar, options, data), 2);
}

Status SaveAvatarSafetensors(const GaussianStyleAvatar& avatar, const nlohmann::json& config, const fs::path& dir) {
  SafeTensorsFile file;
  file.metadata["format"] = "pt";
  file.metadata["model"] = kGaussianStyle.Name();
  try {
    for (const auto& [name, tensor] : NamedTensors(avatar)) file.tensors.push_back(ToSafeTensor(name, tensor));
  } catch (const c10::Error& e) {
    return Status::Internal(e.what_without_backtrace());
  }
  HF_RETURN_IF_ERROR(WriteSafetensors(dir / "weights.safetensors", file));
  return WriteJsonAtomic(dir / "config.json", config, 2);
}

namespace {

// The views a model trained on, as `config` records them.
DatasetOptions TrainedData(const nlohmann::json& config) {
  DatasetOptions data;
  if (config.contains("options")) {
    FromJson(config.at("options").at("data"), &data);
    return data;
  }
  // Written before the options were recorded: at the top.
  data.resolution = config.at("resolution").get<int>();
  data.holdout = config.value("holdout", data.holdout);
  // Models trained before the order existed held out the last frames.
  data.holdout_order = config.value("holdout_order", std::string("last"));
  // Models trained before the mask was chosen trained on the workspace's.
  data.mask = config.value("mask", std::string("ingest"));
  data.mask_hair = config.value("mask_hair", data.mask_hair);
  data.mask_skin = config.value("mask_skin", data.mask_skin);
  return data;
}

}  // namespace

Status LoadAvatar(const fs::path& dir, torch::Device device, GaussianStyleAvatar* avatar, DatasetOptions* trained) {
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadArtefact(dir / "config.json", 1, "train", &config));
  Checkpoint c;
  fs::path weights;
  HF_RETURN_IF_ERROR(Checkpoint::LoadModelWeights(dir, &c, &weights));
  const auto get = [&](const std::string& name, torch::Tensor* t) { return c.Get(name, t); };
  GaussianStyleAvatar out;
  try {
    out.model = GaussianStyle(OptionsFromJson(config.at("architecture")), config.at("frames").get<int64_t>());
    out.deform = config.at("deform").get<bool>();
    if (config.contains("decoder")) out.decoder = StyleDecoder(StyleDecoderOptionsFromJson(config.at("decoder")));
    if (trained) *trained = TrainedData(config);
  } catch (const std::exception& e) {
    return Status::DataError((dir / "config.json").string() + " is damaged (" + e.what() + "); run headforge train again");
  }
  torch::NoGradGuard no_grad;
  const auto load_module = [&](const std::string& prefix, torch::nn::Module& module) {
    for (auto& item : module.named_parameters()) {
      torch::Tensor value;
      if (!get(prefix + item.key(), &value) || !value.sizes().equals(item.value().sizes()))
        return Status::DataError(weights.string() + " does not hold " + prefix + item.key() +
                                 " as config.json describes it; run headforge train again");
      item.value().copy_(value);
    }
    module.to(device);
    return Status::Ok();
  };
  HF_RETURN_IF_ERROR(load_module("model.", *out.model));
  if (out.decoder) HF_RETURN_IF_ERROR(load_module("decoder.", *out.decoder));
  auto params = out.gaussians.params.All();
  for (size_t i = 0; i < params.size(); ++i)
    if (!get(std::string("gaussians.") + kGaussianNames[i], params[i]))
      return Status::DataError(weights.string() + " holds no Gaussians; run headforge train again");
  for (torch::Tensor* t : params) *t = t->to(device);
  if (get("gaussians.binding", &out.gaussians.binding)) out.gaussians.binding = out.gaussians.binding.to(device);
  if (get("pose_corrections", &out.pose_corrections)) out.pose_corrections = out.pose_corrections.to(device);
  *avatar = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
