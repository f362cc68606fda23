// TrainOptions' checks, its JSON form and the summary line: what the train
// stage and a LibTorch-only training from a pack share.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <cstdio>

#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "avatar/train/device.h"
#include "avatar/train_loop_options.h"

namespace headforge {
namespace {

bool IsPowerOfTwo(int v) { return v > 0 && (v & (v - 1)) == 0; }

}  // namespace

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(TrainOptions, model, preset, device, resolution, steps,
    max_minutes, canonical_fraction, deform, mesh_riding, region_weight, latent_dropout, ssim_weight, holdout,
    holdout_order, holdout_cameras, init_gaussians, max_gaussians, densify_from, densify_until, densify_every, grad_threshold,
    lr_network, lr_means, lr_quats, lr_scales, lr_opacity, lr_features, feature_channels, triplane_resolution,
    latent_dim, render_resolution, batch, reconstruction_steps, recon_weight, adversarial_ramp, lr_discriminator,
    r1_gamma, r1_every, ada_target, collapse_steps, coarse_samples, fine_samples, mapping_samples, mapping_steps, mapping_loss,
    landmark_model, generator_from, decoder_steps, prior_steps, pti_steps, pti_frames, decoder_resolution, projected_blocks,
    adversarial_weight, perceptual_weight, decoder_ada, full_tune, decoder_init, log_every, eval_every,
    preview_every, checkpoint_every, seed)

// The mask's two options are set apart: the macro above takes at most 64 names.
nlohmann::json ToJson(const TrainOptions& options) {
  nlohmann::json j = options;
  j["mask"] = options.mask;
  j["mask_hair"] = options.mask_hair;
  j["mask_skin"] = options.mask_skin;
  j["pose_lr"] = options.pose_lr;
  j["mapping_latents"] = options.mapping_latents;
  j["decoder_max_minutes"] = options.decoder_max_minutes;
  j["validation"] = options.validation;
  j["patience"] = options.patience;
  return j;
}

TrainOptions TrainOptionsFromJson(const nlohmann::json& j) {
  TrainOptions options = j.get<TrainOptions>();
  options.mask = j.value("mask", options.mask);
  options.mask_hair = j.value("mask_hair", options.mask_hair);
  options.mask_skin = j.value("mask_skin", options.mask_skin);
  options.pose_lr = j.value("pose_lr", options.pose_lr);
  options.mapping_latents = j.value("mapping_latents", options.mapping_latents);
  options.decoder_max_minutes = j.value("decoder_max_minutes", options.decoder_max_minutes);
  options.validation = j.value("validation", options.validation);
  options.patience = j.value("patience", options.patience);
  return options;
}

Status TrainOptions::Check() const {
  torch::Device parsed = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseDevice("train", device, &parsed));
  if (!FindAvatarModel(model))
    return Status::InvalidArgument("train: --model must be " + AvatarModelNames() + ", not '" + model + "'");
  if (resolution < 16 || resolution > 4096) return Status::InvalidArgument("train: --train-size must be in [16, 4096]");
  if (steps < 1) return Status::InvalidArgument("train: --steps must be at least 1");
  if (!(max_minutes >= 0)) return Status::InvalidArgument("train: --max-minutes must be zero or positive");
  if (!(validation >= 0 && validation <= 0.5))
    return Status::InvalidArgument("train: --validation must be in [0, 0.5]");
  if (patience < 0) return Status::InvalidArgument("train: --patience must be zero or positive");
  if (!(decoder_max_minutes >= 0))
    return Status::InvalidArgument("train: --decoder-max-minutes must be zero or positive");
  if (!(canonical_fraction >= 0 && canonical_fraction <= 1))
    return Status::InvalidArgument("train: --canonical-fraction must be in [0, 1]");
  if (!(latent_dropout >= 0 && latent_dropout <= 1))
    return Status::InvalidArgument("train: --latent-dropout must be in [0, 1]");
  if (!(region_weight >= 0) || !(ssim_weight >= 0 && ssim_weight <= 1))
    return Status::InvalidArgument("train: --region-weight must be >= 0 and --ssim-weight in [0, 1]");
  if (!(holdout > 0 && holdout < 0.9)) return Status::InvalidArgument("train: --holdout must be in (0, 0.9)");
  if (holdout_order != "auto" && holdout_order != "last" && holdout_order != "interleaved")
    return Status::InvalidArgument("train: --holdout-order must be auto, last or interleaved, not '" + holdout_order +
                                   "'");
  if (mask != "auto" && mask != "ingest" && mask != "mesh")
    return Status::InvalidArgument("train: --mask must be auto, ingest or mesh, not '" + mask +
                                   "' (your own masks: a folder given to ingest's --mask-folder)");
  if (!(mask_hair >= 0 && mask_hair <= 0.3) || !(mask_skin >= 0 && mask_skin <= 0.3))
    return Status::InvalidArgument("train: --mask-hair and --mask-skin must be in [0, 0.3] metres");
  if (!(pose_lr >= 0)) return Status::InvalidArgument("train: --pose-lr must be zero or positive");
  if (init_gaussians < 1 || max_gaussians < init_gaussians)
    return Status::InvalidArgument("train: --init-gaussians must be positive and at most --max-gaussians");
  if (densify_every < 1) return Status::InvalidArgument("train: --densify-every must be at least 1");
  for (double lr : {lr_network, lr_means, lr_quats, lr_scales, lr_opacity, lr_features})
    if (!(lr >= 0)) return Status::InvalidArgument("train: learning rates must be zero or positive");
  if (feature_channels < 3) return Status::InvalidArgument("train: --feature-channels must be at least 3 (RGB)");
  if (triplane_resolution < 8 || (triplane_resolution & (triplane_resolution - 1)) != 0)
    return Status::InvalidArgument("train: --triplane-resolution must be a power of two of at least 8");
  if (latent_dim < 1) return Status::InvalidArgument("train: --latent-dim must be positive");
  if (kGanAvatar.Is(model)) {
    if (render_resolution < 4 || render_resolution > resolution ||
        resolution % render_resolution != 0 || !IsPowerOfTwo(resolution / render_resolution))
      return Status::InvalidArgument("train: --render-resolution must divide --train-size by a power of two (" +
                                     std::to_string(render_resolution) + " into " + std::to_string(resolution) + ")");
    if (batch < 1) return Status::InvalidArgument("train: --batch must be at least 1");
    if (reconstruction_steps < 0 || adversarial_ramp < 0 || !(recon_weight >= 0))
      return Status::InvalidArgument(
          "train: --reconstruction-steps, --adversarial-ramp and --recon-weight must be zero or positive");
    if (!(lr_discriminator >= 0) || !(r1_gamma >= 0) || r1_every < 1)
      return Status::InvalidArgument("train: --lr-discriminator and --r1-gamma must be >= 0, --r1-every >= 1");
    if (!(ada_target > 0 && ada_target < 1)) return Status::InvalidArgument("train: --ada-target must be in (0, 1)");
    if (mapping_loss != "image" && mapping_loss != "latent")
      return Status::InvalidArgument("train: --mapping-loss must be image or latent, not '" + mapping_loss + "'");
    if (mapping_latents != "random" && mapping_latents != "frames")
      return Status::InvalidArgument("train: --mapping-latents must be random or frames, not '" +
                                     mapping_latents + "'");
    if (mapping_latents == "frames" && generator_from.empty() && reconstruction_steps == 0 && !(recon_weight > 0))
      return Status::InvalidArgument("train: --mapping-latents frames renders the latents the reconstruction loss fits "
                                     "to the training frames, and with --reconstruction-steps 0 and --recon-weight 0 "
                                     "there are none; use --mapping-latents random");
    if (mapping_samples < 1 || mapping_steps < 0)
      return Status::InvalidArgument("train: --mapping-samples must be at least 1 and --mapping-steps at least 0");
    if (coarse_samples < 1 || fine_samples < 0)
      return Status::InvalidArgument("train: --samples must be at least 1 and --fine-samples at least 0");
  } else if (!generator_from.empty()) {
    return Status::InvalidArgument("train: --generator-from is for the gan-avatar model (--model gan-avatar)");
  }
  if (kGaussianStyle.Is(model) && decoder_steps > 0) {
    const int side = decoder_resolution > 0 ? decoder_resolution : resolution;
    if (side < 8 || !IsPowerOfTwo(side))
      return Status::InvalidArgument("train: the decoder's side (--decoder-resolution, else --train-size) must be a "
                                     "power of two of at least 8, not " + std::to_string(side));
    if (prior_steps < 0 || pti_steps < 0 || pti_frames < 1 || projected_blocks < 0 || batch < 1)
      return Status::InvalidArgument("train: --prior-steps and --pti-steps must be >= 0, --pti-frames and --batch >= 1, "
                                     "--projected-blocks >= 0");
    if (!(adversarial_weight >= 0) || !(perceptual_weight >= 0) || !(r1_gamma >= 0) || r1_every < 1 ||
        !(ada_target > 0 && ada_target < 1) || !(lr_discriminator >= 0))
      return Status::InvalidArgument("train: --adversarial-weight, --perceptual-weight, --r1-gamma and "
                                     "--lr-discriminator must be >= 0, --r1-every >= 1, --ada-target in (0, 1)");
    std::error_code ec;
    if (!decoder_init.empty() && !fs::is_regular_file(decoder_init, ec))
      return Status::InvalidArgument("train: --decoder-init: no file " + decoder_init);
  }
  if (collapse_steps < 0) return Status::InvalidArgument("train: --collapse-steps must be zero or positive");
  if (log_every < 1 || eval_every < 0 || preview_every < 0 || checkpoint_every < 1)
    return Status::InvalidArgument("train: --log-every and --checkpoint-every must be >= 1, the others >= 0");
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
  return note.empty() ? std::string(text) : std::string(text) + "; " + note;
}

LoopOptions TrainLoopOptions(const TrainOptions& options, const std::string& label, int steps) {
  LoopOptions loop;
  loop.label = label;
  loop.steps = steps;
  loop.max_minutes = options.max_minutes;
  loop.log_every = options.log_every;
  loop.eval_every = options.eval_every;
  loop.preview_every = options.preview_every;
  loop.checkpoint_every = options.checkpoint_every;
  return loop;
}

}  // namespace headforge
