#include "avatar/gan_avatar/avatar_io.h"

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "avatar/model_table.h"
#include "avatar/train/checkpoint.h"
#include "core/json_io.h"

namespace headforge {

bool IsGanAvatarFolder(const fs::path& dir) {
  nlohmann::json config;
  return ReadJson(dir / "config.json", &config).ok() && kGanAvatar.Is(config.value("model", ""));
}

namespace {

// The views `config`'s model trained on: in its options' "data" block, or,
// in models written before the blocks, in "training" (the mask resolved
// there).
DatasetOptions TrainedData(const nlohmann::json& config) {
  DatasetOptions data;
  data.holdout_order = "last";
  const auto options = config.find("options");
  if (options != config.end() && options->contains("data")) {
    FromJson(options->at("data"), &data);
  } else if (config.contains("training")) {
    const nlohmann::json& training = config.at("training");
    data.holdout = training.value("holdout", data.holdout);
    data.holdout_order = training.value("holdout_order", data.holdout_order);
    data.holdout_cameras = training.value("holdout_cameras", std::vector<std::string>());
    data.mask = training.value("mask", data.mask);
    data.mask_hair = training.value("mask_hair", data.mask_hair);
    data.mask_skin = training.value("mask_skin", data.mask_skin);
  }
  data.auto_mask = std::string(kGanAvatar.default_mask);
  return data;
}

}  // namespace

Status LoadGanAvatar(const fs::path& dir, torch::Device device, GanAvatar* avatar) {
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadJson(dir / "config.json", &config));
  const Status damaged = Status::DataError(dir.string() + " does not hold a gan-avatar model this version reads; "
                                                          "run headforge train --model gan-avatar again");
  if (!kGanAvatar.Is(config.value("model", "")) || config.value("version", 0) != 1) return damaged;
  GanAvatarOptions arch;
  try {
    config.at("architecture").get_to(arch);
    avatar->render_width = config.at("render_size").at(0);
    avatar->render_height = config.at("render_size").at(1);
    avatar->out_width = config.at("output_size").at(0);
    avatar->out_height = config.at("output_size").at(1);
    avatar->background = config.at("background");
    avatar->expressions = int64_t(config.at("expression_mapping").at("expressions").size());
    avatar->trained = TrainedData(config);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(dir.string() + "/config.json: " + e.what());
  }
  Checkpoint weights;
  fs::path file;
  HF_RETURN_IF_ERROR(Checkpoint::LoadModelWeights(dir, &weights, &file));
  avatar->generator = GanGenerator(arch);
  if (!weights.GetModule("generator.", avatar->generator.get()) || !weights.Get("w_average", &avatar->w_average))
    return damaged;
  if (config.at("expression_mapping").value("trained", false)) {
    avatar->mapping = ExpressionMapping(avatar->expressions, arch.w_dim);
    if (!weights.GetModule("mapping.", avatar->mapping.get())) return damaged;
    avatar->mapping->to(device);
  }
  if (weights.Get("frame_codes", &avatar->frame_codes) && weights.Get("trained_frames", &avatar->trained_frames))
    avatar->frame_codes = avatar->frame_codes.to(device);
  else
    avatar->frame_codes = avatar->trained_frames = torch::Tensor();
  avatar->generator->to(device);
  avatar->w_average = avatar->w_average.to(device);
  return Status::Ok();
}

Status ExportGanAvatarWeights(const fs::path& model_dir, const nlohmann::json& extra, const fs::path& out_dir) {
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadJson(model_dir / "config.json", &config));
  Checkpoint weights;
  fs::path file;
  HF_RETURN_IF_ERROR(Checkpoint::LoadModelWeights(model_dir, &weights, &file));
  config.update(extra);
  config["tensors"] = {
      {"generator.*", "the 3D GAN's generator (mapping z -> w, plane synthesis, decoder MLP, super-resolution), "
                      "named by module path"},
      {"w_average", "[w_dim] the running mean of w: the avatar's latent without an expression"},
      {"mapping.*", "the expression mapping, expression weights -> w (when trained)"},
      {"frame_codes", "[frames, z_dim] the reconstruction warm-up's latent z of each frame (models since they were "
                      "kept)"},
      {"trained_frames", "the frames (rows of frame_codes) the warm-up trained; the others' rows are untrained"}};
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  HF_RETURN_IF_ERROR(weights.SaveSafetensors(out_dir / "weights.safetensors", {{"format", "pt"}, {"model", kGanAvatar.Name()}}));
  return WriteJsonAtomic(out_dir / "config.json", config, 2);
}

torch::Tensor GanAvatar::Draw(const torch::Tensor& e, const SplatCamera& camera) {
  torch::NoGradGuard no_grad;
  const torch::Device device = w_average.device();
  torch::Tensor w = w_average.unsqueeze(0);
  if (mapping && e.defined()) w = mapping->forward(e.narrow(0, 0, expressions).unsqueeze(0).to(device, torch::kFloat32));
  const SplatCamera small = camera.Downscaled(double(camera.width) / render_width);
  return generator->Render(w, {small}, camera.width, camera.height, background, nullptr).image.clamp(0, 1).cpu()[0];
}

}  // namespace headforge
