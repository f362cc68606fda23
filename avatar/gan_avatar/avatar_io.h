// A trained gan-avatar model read back from its folder (model.pt and
// config.json, as TrainGanAvatar writes them), and drawn: a tracked
// expression through the expression mapping to w, rendered from a camera.
#pragma once

#include <torch/types.h>

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "avatar/gan_avatar/expression_mapping.h"
#include "avatar/gan_avatar/model.h"
#include "avatar/train/dataset_options.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct GanAvatar {
  GanGenerator generator{nullptr};
  ExpressionMapping mapping{nullptr};  // null when training mapped no expressions
  torch::Tensor w_average;             // [w_dim]
  // The reconstruction warm-up's latent z of each frame [frames, z_dim] and
  // the frames it trained (undefined in models written before they were kept).
  torch::Tensor frame_codes, trained_frames;
  int render_width = 0, render_height = 0, out_width = 0, out_height = 0;
  double background = 0.5;
  int64_t expressions = 0;
  // The views it trained on, as its config.json records them: what training
  // held out (frames and whole cameras) and the masks (resolved: ingest or
  // mesh). Models written before they were recorded held out the last 20% of
  // the frames and trained on the workspace's masks.
  DatasetOptions trained;

  // The image [3, H, W] (on the CPU, in [0, 1]) for `expressions` [E] (the
  // mean latent when undefined or without a mapping) from `camera`, a camera
  // at the output size (rendered at the volume render's size, then
  // super-resolved).
  torch::Tensor Draw(const torch::Tensor& expressions, const SplatCamera& camera);
};

// True when `dir`'s config.json names the gan-avatar model.
bool IsGanAvatarFolder(const fs::path& dir);
// From model.pt, or weights.safetensors as export writes it.
Status LoadGanAvatar(const fs::path& dir, torch::Device device, GanAvatar* avatar);
// The model in `model_dir` as weights.safetensors + config.json (its own,
// with `extra` merged in and the tensors described) in `out_dir`.
Status ExportGanAvatarWeights(const fs::path& model_dir, const nlohmann::json& extra, const fs::path& out_dir);

}  // namespace headforge
