// The gan-avatar model's training options (TrainOptions::gan_avatar,
// avatar_train.h), their presets and their record. No LibTorch here:
// pipelines/ reads them. Each field's name is its dotted key's last part
// (train.render_resolution) and its name in a record. Its GAN also reads
// train's shared options: --batch, --lr-discriminator, --r1-gamma,
// --r1-every, --ada-target and --collapse-steps (which gaussian-style's
// stage 3 reads too), and the networks' --lr-network, --latent-dim,
// --triplane-resolution and --feature-channels.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <string>

#include "core/status.h"

namespace headforge {

class OptionSet;

struct GanAvatarTrainOptions {
  // The volume render's longer side (--train-size is the super-resolved
  // output's; their ratio a power of two).
  int render_resolution = 32;
  int reconstruction_steps = 0;  // the warm-up's steps before the adversarial ones
  double recon_weight = 1.0;     // the reconstruction's weight after the warm-up (0: none)
  int adversarial_ramp = 300;    // steps over which the adversarial loss comes in
  int coarse_samples = 24, fine_samples = 24;  // samples per ray: stratified, then importance
  // The expression mapping: renders sampled and tracked, steps, loss
  // ("image": photometric, the paper's; "latent": the ablation), and the
  // landmark model that reads the renders.
  int mapping_samples = 256;
  int mapping_steps = 300;
  std::string mapping_loss = "image";
  // Which latents the mapping's renders come from: "random" (z ~ N(0, I),
  // the paper's) or "frames" (the reconstruction warm-up's latents of the
  // training frames, then blends of two).
  std::string mapping_latents = "random";
  std::string landmark_model;
  // A folder where the GAN was trained already (headforge-train's output for
  // this workspace's pack, on a GPU machine): its generator is taken and
  // only the expression mapping trains; the options that shape the model and
  // its views come from that folder's config.json.
  std::string generator_from;

  // Its options alone (TrainOptions::Check sets the render's size against
  // the training size and checks the shared GAN options).
  Status Check() const;
};

// By field name; reading gives a field `j` lacks its default.
nlohmann::json ToJson(const GanAvatarTrainOptions& options);
void FromJson(const nlohmann::json& j, GanAvatarTrainOptions* options);

// What a preset sets: each also an option of its own, train's common ones
// (device, training size, steps, cadence, networks, GANs) beside the model's.
struct GanAvatarPreset {
  std::string device;
  int resolution = 0, render_resolution = 0, steps = 0;
  double max_minutes = 0;
  int eval_every = 0, preview_every = 0;
  int triplane_resolution = 0;
  double lr_network = 0;
  int batch = 0, reconstruction_steps = 0;
  double lr_discriminator = 0, r1_gamma = 0;
};

// draft, standard or high; false for a name that is none.
bool FindGanAvatarPreset(const std::string& name, GanAvatarPreset* preset);

// Binds the options to their dotted keys (train.render_resolution, ...) and
// short flags. The full build's (register_options.cc): the LibTorch-only
// build has no command line.
void AddGanAvatarOptions(OptionSet* options, GanAvatarTrainOptions* gan_avatar);

}  // namespace headforge
