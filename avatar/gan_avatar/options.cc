// The gan-avatar model's training options: their checks, record and presets
// (both builds; the command line's side is register_options.cc).
#include "avatar/gan_avatar/options.h"

#include <nlohmann/json.hpp>

namespace headforge {

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(GanAvatarTrainOptions, render_resolution, reconstruction_steps,
                                                recon_weight, adversarial_ramp, coarse_samples, fine_samples,
                                                mapping_samples, mapping_steps, mapping_loss, mapping_latents,
                                                landmark_model, generator_from)

Status GanAvatarTrainOptions::Check() const {
  if (reconstruction_steps < 0 || adversarial_ramp < 0 || !(recon_weight >= 0))
    return Status::InvalidArgument(
        "train: --reconstruction-steps, --adversarial-ramp and --recon-weight must be zero or positive");
  if (mapping_loss != "image" && mapping_loss != "latent")
    return Status::InvalidArgument("train: --mapping-loss must be image or latent, not '" + mapping_loss + "'");
  if (mapping_latents != "random" && mapping_latents != "frames")
    return Status::InvalidArgument("train: --mapping-latents must be random or frames, not '" + mapping_latents +
                                   "'");
  if (mapping_latents == "frames" && generator_from.empty() && reconstruction_steps == 0 && !(recon_weight > 0))
    return Status::InvalidArgument("train: --mapping-latents frames renders the latents the reconstruction loss fits "
                                   "to the training frames, and with --reconstruction-steps 0 and --recon-weight 0 "
                                   "there are none; use --mapping-latents random");
  if (mapping_samples < 1 || mapping_steps < 0)
    return Status::InvalidArgument("train: --mapping-samples must be at least 1 and --mapping-steps at least 0");
  if (coarse_samples < 1 || fine_samples < 0)
    return Status::InvalidArgument("train: --samples must be at least 1 and --fine-samples at least 0");
  return Status::Ok();
}

nlohmann::json ToJson(const GanAvatarTrainOptions& options) { return options; }

void FromJson(const nlohmann::json& j, GanAvatarTrainOptions* options) { *options = j.get<GanAvatarTrainOptions>(); }

namespace {

// draft: a 32 px volume render super-resolved to 64 px on two CPU cores,
// every step the reconstruction warm-up (measured: within 15 minutes the
// adversarial steps cost 4 dB on the held-out frames, docs/benchmarks.md);
// standard and high: EG3D's render sizes on one GPU, a warm-up and then the
// GAN (docs/gan_avatar.md). The step sizes are EG3D's 0.0025 over ten: the
// layers here have no equalised learning rate, so their weights are about ten
// times smaller and the same step moves them ten times as far (measured: at
// 2e-3 the discriminator wins within 50 steps).
GanAvatarPreset Draft() {
  GanAvatarPreset p;
  p.device = "cpu";
  p.resolution = 64;
  p.render_resolution = 32;
  p.steps = 1800;
  p.max_minutes = 15;
  p.eval_every = 300;
  p.preview_every = 300;
  p.triplane_resolution = 64;
  p.lr_network = 2.5e-4;
  p.batch = 4;
  p.reconstruction_steps = 1800;
  p.lr_discriminator = 2.5e-4;
  p.r1_gamma = 1.0;
  return p;
}

GanAvatarPreset Standard() {
  GanAvatarPreset p;
  p.device = "cuda";
  p.resolution = 256;
  p.render_resolution = 64;
  p.steps = 40000;
  p.max_minutes = 60;
  p.eval_every = 2000;
  p.preview_every = 2000;
  p.triplane_resolution = 128;
  p.lr_network = 2.5e-4;
  p.batch = 8;
  p.reconstruction_steps = 10000;
  p.lr_discriminator = 2.5e-4;
  p.r1_gamma = 1.0;
  return p;
}

GanAvatarPreset High() {
  GanAvatarPreset p;
  p.device = "cuda";
  p.resolution = 512;
  p.render_resolution = 128;
  p.steps = 200000;
  p.max_minutes = 0;
  p.eval_every = 5000;
  p.preview_every = 5000;
  p.triplane_resolution = 256;
  p.lr_network = 2.5e-4;
  p.batch = 16;
  p.reconstruction_steps = 20000;
  p.lr_discriminator = 2.5e-4;
  p.r1_gamma = 1.0;
  return p;
}

}  // namespace

bool FindGanAvatarPreset(const std::string& name, GanAvatarPreset* preset) {
  if (name == "draft") *preset = Draft();
  else if (name == "standard") *preset = Standard();
  else if (name == "high") *preset = High();
  else return false;
  return true;
}

}  // namespace headforge
