// TrainOptions' checks, its JSON form and the summary line: what the train
// stage and a LibTorch-only training from a pack share.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <string_view>

#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "avatar/train/device.h"
#include "avatar/train_loop_options.h"

namespace headforge {
namespace {

bool IsPowerOfTwo(int v) { return v > 0 && (v & (v - 1)) == 0; }

// The block `name` of `j`, or `j` itself where it has none (the flat record).
const nlohmann::json& Block(const nlohmann::json& j, std::string_view name) {
  const auto it = j.find(std::string(name));
  return it != j.end() && it->is_object() ? *it : j;
}

}  // namespace

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(TrainLoopSettings, steps, max_minutes, log_every, eval_every,
                                                preview_every, checkpoint_every)

nlohmann::json ToJson(const TrainOptions& options) {
  nlohmann::json j = {{"model", options.model},
                      {"preset", options.preset},
                      {"device", options.device},
                      {"seed", options.seed},
                      {"lr_network", options.lr_network},
                      {"feature_channels", options.feature_channels},
                      {"triplane_resolution", options.triplane_resolution},
                      {"latent_dim", options.latent_dim},
                      {"batch", options.batch},
                      {"lr_discriminator", options.lr_discriminator},
                      {"r1_gamma", options.r1_gamma},
                      {"r1_every", options.r1_every},
                      {"ada_target", options.ada_target},
                      {"collapse_steps", options.collapse_steps},
                      {"data", ToJson(options.data)},
                      {"loop", options.loop}};
  // A model's block under its folder's name.
  if (kGaussianStyle.Is(options.model)) j[std::string(kGaussianStyle.folder)] = ToJson(options.gaussian_style);
  if (kGanAvatar.Is(options.model)) j[std::string(kGanAvatar.folder)] = ToJson(options.gan_avatar);
  return j;
}

TrainOptions TrainOptionsFromJson(const nlohmann::json& j) {
  TrainOptions options;
  options.model = j.value("model", options.model);
  options.preset = j.value("preset", options.preset);
  options.device = j.value("device", options.device);
  options.seed = j.value("seed", options.seed);
  options.lr_network = j.value("lr_network", options.lr_network);
  options.feature_channels = j.value("feature_channels", options.feature_channels);
  options.triplane_resolution = j.value("triplane_resolution", options.triplane_resolution);
  options.latent_dim = j.value("latent_dim", options.latent_dim);
  options.batch = j.value("batch", options.batch);
  options.lr_discriminator = j.value("lr_discriminator", options.lr_discriminator);
  options.r1_gamma = j.value("r1_gamma", options.r1_gamma);
  options.r1_every = j.value("r1_every", options.r1_every);
  options.ada_target = j.value("ada_target", options.ada_target);
  options.collapse_steps = j.value("collapse_steps", options.collapse_steps);
  FromJson(Block(j, "data"), &options.data);
  options.loop = Block(j, "loop").get<TrainLoopSettings>();
  FromJson(Block(j, kGaussianStyle.folder), &options.gaussian_style);
  FromJson(Block(j, kGanAvatar.folder), &options.gan_avatar);
  return options;
}

Status TrainLoopSettings::Check() const {
  if (steps < 1) return Status::InvalidArgument("train: --steps must be at least 1");
  if (!(max_minutes >= 0)) return Status::InvalidArgument("train: --max-minutes must be zero or positive");
  if (log_every < 1 || eval_every < 0 || preview_every < 0 || checkpoint_every < 1)
    return Status::InvalidArgument("train: --log-every and --checkpoint-every must be >= 1, the others >= 0");
  return Status::Ok();
}

namespace {

// The gan-avatar model's options against the common ones it reads.
Status CheckGanAvatar(const TrainOptions& t) {
  const int resolution = t.data.resolution, render_resolution = t.gan_avatar.render_resolution;
  if (render_resolution < 4 || render_resolution > resolution || resolution % render_resolution != 0 ||
      !IsPowerOfTwo(resolution / render_resolution))
    return Status::InvalidArgument("train: --render-resolution must divide --train-size by a power of two (" +
                                   std::to_string(render_resolution) + " into " + std::to_string(resolution) + ")");
  if (t.batch < 1) return Status::InvalidArgument("train: --batch must be at least 1");
  if (!(t.lr_discriminator >= 0) || !(t.r1_gamma >= 0) || t.r1_every < 1)
    return Status::InvalidArgument("train: --lr-discriminator and --r1-gamma must be >= 0, --r1-every >= 1");
  if (!(t.ada_target > 0 && t.ada_target < 1)) return Status::InvalidArgument("train: --ada-target must be in (0, 1)");
  return t.gan_avatar.Check();
}

// Stage 3's options (gaussian-style's decoder) with the common ones its GANs read.
Status CheckStyleDecoder(const TrainOptions& t) {
  const DecoderTrainOptions& d = t.gaussian_style.decoder;
  const int side = d.decoder_resolution > 0 ? d.decoder_resolution : t.data.resolution;
  if (side < 8 || !IsPowerOfTwo(side))
    return Status::InvalidArgument("train: the decoder's side (--decoder-resolution, else --train-size) must be a "
                                   "power of two of at least 8, not " + std::to_string(side));
  if (d.prior_steps < 0 || d.pti_steps < 0 || d.pti_frames < 1 || d.projected_blocks < 0 || t.batch < 1)
    return Status::InvalidArgument("train: --prior-steps and --pti-steps must be >= 0, --pti-frames and --batch >= 1, "
                                   "--projected-blocks >= 0");
  if (!(d.adversarial_weight >= 0) || !(d.perceptual_weight >= 0) || !(t.r1_gamma >= 0) || t.r1_every < 1 ||
      !(t.ada_target > 0 && t.ada_target < 1) || !(t.lr_discriminator >= 0))
    return Status::InvalidArgument("train: --adversarial-weight, --perceptual-weight, --r1-gamma and "
                                   "--lr-discriminator must be >= 0, --r1-every >= 1, --ada-target in (0, 1)");
  std::error_code ec;
  if (!d.decoder_init.empty() && !fs::is_regular_file(d.decoder_init, ec))
    return Status::InvalidArgument("train: --decoder-init: no file " + d.decoder_init);
  return Status::Ok();
}

}  // namespace

Status TrainOptions::Check() const {
  torch::Device parsed = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseDevice("train", device, &parsed));
  if (!FindAvatarModel(model)) {
    if (const AvatarModel* exported = FindAnyAvatarModel(model))
      return Status::InvalidArgument("train: " + exported->Name() + " is not trained but exported from a trained " +
                                     std::string(exported->made_from) + " avatar: train that, then headforge export " +
                                     "--formats " + std::string(exported->export_format));
    return Status::InvalidArgument("train: --model must be " + AvatarModelNames() + ", not '" + model + "'");
  }
  HF_RETURN_IF_ERROR(data.Check());
  HF_RETURN_IF_ERROR(loop.Check());
  // The gaussian-style model's stages 1-2 are checked whichever model trains, as they always were.
  HF_RETURN_IF_ERROR(gaussian_style.Check());
  if (!(lr_network >= 0)) return Status::InvalidArgument("train: learning rates must be zero or positive");
  if (feature_channels < 3) return Status::InvalidArgument("train: --feature-channels must be at least 3 (RGB)");
  if (triplane_resolution < 8 || (triplane_resolution & (triplane_resolution - 1)) != 0)
    return Status::InvalidArgument("train: --triplane-resolution must be a power of two of at least 8");
  if (latent_dim < 1) return Status::InvalidArgument("train: --latent-dim must be positive");
  if (kGanAvatar.Is(model)) {
    HF_RETURN_IF_ERROR(CheckGanAvatar(*this));
  } else if (!gan_avatar.generator_from.empty()) {
    return Status::InvalidArgument("train: --generator-from is for the gan-avatar model (--model gan-avatar)");
  }
  if (kGaussianStyle.Is(model) && gaussian_style.decoder.decoder_steps > 0)
    HF_RETURN_IF_ERROR(CheckStyleDecoder(*this));
  if (collapse_steps < 0) return Status::InvalidArgument("train: --collapse-steps must be zero or positive");
  return Status::Ok();
}

std::string TrainSummary::OneLine() const {
  char text[320];
  const std::string resumed = resumed_from > 0 ? " (resumed at step " + std::to_string(resumed_from) + ")" : "";
  const std::string count = gaussians > 0 ? ", " + std::to_string(gaussians) + " Gaussians" : "";
  std::snprintf(text, sizeof(text),
                "%d steps in %.0f s%s%s; %d held-out views: PSNR %.2f dB / SSIM %.3f over the head, "
                "%.2f dB / %.3f over the frame",
                steps, seconds, resumed.c_str(), count.c_str(), test_views, psnr_masked, ssim_masked, psnr_full,
                ssim_full);
  std::string line = note.empty() ? std::string(text) : std::string(text) + "; " + note;
  if (extendable) line += "; stopped by the time limit (train --extend --max-minutes M goes on from there)";
  return line;
}

LoopOptions TrainLoopOptions(const TrainLoopSettings& settings, const std::string& label, int steps) {
  LoopOptions loop;
  loop.label = label;
  loop.steps = steps;
  loop.max_minutes = settings.max_minutes;
  loop.log_every = settings.log_every;
  loop.eval_every = settings.eval_every;
  loop.preview_every = settings.preview_every;
  loop.checkpoint_every = settings.checkpoint_every;
  return loop;
}

}  // namespace headforge
