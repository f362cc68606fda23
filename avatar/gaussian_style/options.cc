// The gaussian-style model's training options: their checks, record and
// presets (both builds; the command line's side is register_options.cc).
#include "avatar/gaussian_style/options.h"

#include <nlohmann/json.hpp>

namespace headforge {

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(DecoderTrainOptions, decoder_steps, decoder_max_minutes, prior_steps,
                                                pti_steps, pti_frames, decoder_resolution, projected_blocks,
                                                adversarial_weight, perceptual_weight, decoder_ada, full_tune,
                                                decoder_init)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(GaussianStyleTrainOptions, canonical_fraction, deform, mesh_riding,
                                                region_weight, latent_dropout, ssim_weight, validation, patience,
                                                pose_lr, views_per_step, init_gaussians, max_gaussians, densify_from, densify_until,
                                                densify_every, grad_threshold, lr_means, lr_quats, lr_scales,
                                                lr_opacity, lr_features, decoder)

Status GaussianStyleTrainOptions::Check() const {
  if (!(validation >= 0 && validation <= 0.5))
    return Status::InvalidArgument("train: --validation must be in [0, 0.5]");
  if (patience < 0) return Status::InvalidArgument("train: --patience must be zero or positive");
  if (!(decoder.decoder_max_minutes >= 0))
    return Status::InvalidArgument("train: --decoder-max-minutes must be zero or positive");
  if (!(canonical_fraction >= 0 && canonical_fraction <= 1))
    return Status::InvalidArgument("train: --canonical-fraction must be in [0, 1]");
  if (!(latent_dropout >= 0 && latent_dropout <= 1))
    return Status::InvalidArgument("train: --latent-dropout must be in [0, 1]");
  if (!(region_weight >= 0) || !(ssim_weight >= 0 && ssim_weight <= 1))
    return Status::InvalidArgument("train: --region-weight must be >= 0 and --ssim-weight in [0, 1]");
  if (!(pose_lr >= 0)) return Status::InvalidArgument("train: --pose-lr must be zero or positive");
  if (views_per_step < 0 || views_per_step > 64)
    return Status::InvalidArgument("train: --views-per-step must be in [0, 64] (0: one per rank)");
  if (init_gaussians < 1 || max_gaussians < init_gaussians)
    return Status::InvalidArgument("train: --init-gaussians must be positive and at most --max-gaussians");
  if (densify_every < 1) return Status::InvalidArgument("train: --densify-every must be at least 1");
  for (double lr : {lr_means, lr_quats, lr_scales, lr_opacity, lr_features})
    if (!(lr >= 0)) return Status::InvalidArgument("train: learning rates must be zero or positive");
  return Status::Ok();
}

nlohmann::json ToJson(const GaussianStyleTrainOptions& options) {
  nlohmann::json j = options;
  // Left out at its default, so that the records (and the train stage's
  // fingerprint) of runs that never set it stay as they were.
  if (options.views_per_step == 0) j.erase("views_per_step");
  return j;
}

void FromJson(const nlohmann::json& j, GaussianStyleTrainOptions* options) {
  *options = j.get<GaussianStyleTrainOptions>();
  if (!j.contains("decoder")) options->decoder = j.get<DecoderTrainOptions>();
}

namespace {

// draft: measured on two CPU cores to end within its 15 minutes
// (docs/benchmarks.md); standard: one GPU at 512 px, at most 100 000
// Gaussians (measured on an H200: 25.95 dB held-out and 7.6 ms a frame,
// against 25.08 dB and 14.7 ms with 300 000); high: the paper's learning rate
// and a long run.
GaussianStylePreset Draft() {
  GaussianStylePreset p;
  p.device = "cpu";
  p.resolution = 256;
  p.steps = 6000;
  p.max_minutes = 15;
  p.eval_every = 1000;
  p.preview_every = 1000;
  p.triplane_resolution = 64;
  p.lr_network = 5e-4;
  p.init_gaussians = 20000;
  p.max_gaussians = 40000;
  p.densify_until = 3000;
  p.validation = 0;
  p.patience = 0;
  p.decoder_steps = 0;
  p.prior_steps = 0;
  p.pti_steps = 0;
  return p;
}

GaussianStylePreset Standard() {
  GaussianStylePreset p;
  p.device = "cuda";
  p.resolution = 512;
  p.steps = 30000;
  p.max_minutes = 10;
  p.eval_every = 2000;
  p.preview_every = 2000;
  p.triplane_resolution = 128;
  p.lr_network = 2e-4;
  p.init_gaussians = 50000;
  p.max_gaussians = 100000;
  p.densify_until = 20000;
  p.validation = 0;
  p.patience = 0;
  p.decoder_steps = 20000;
  p.prior_steps = 20000;
  p.pti_steps = 500;
  return p;
}

GaussianStylePreset High() {
  GaussianStylePreset p;
  p.device = "cuda";
  p.resolution = 512;
  p.steps = 100000;
  p.max_minutes = 0;
  p.eval_every = 5000;
  p.preview_every = 5000;
  p.triplane_resolution = 256;
  p.lr_network = 1e-4;
  p.init_gaussians = 100000;
  p.max_gaussians = 500000;
  p.densify_until = 60000;
  p.validation = 0;
  p.patience = 0;
  p.decoder_steps = 50000;
  p.prior_steps = 50000;
  p.pti_steps = 1000;
  return p;
}

}  // namespace

bool FindGaussianStylePreset(const std::string& name, GaussianStylePreset* preset) {
  if (name == "draft") *preset = Draft();
  else if (name == "standard") *preset = Standard();
  else if (name == "high") *preset = High();
  else return false;
  return true;
}

}  // namespace headforge
