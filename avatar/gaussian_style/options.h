// The gaussian-style model's training options (TrainOptions::gaussian_style,
// avatar_train.h), their presets and their record. No LibTorch here:
// pipelines/ reads them. Each field's name is its dotted key's last part
// (train.canonical_fraction) and its name in a record.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <string>

#include "core/status.h"

namespace headforge {

class OptionSet;

// Stage 3, the StyleGAN decoder: its steps (0: no stage 3), the personal
// prior's steps (the generator trained on the frames), PTI's steps (each
// half) and frames, the decoder's side (0: --train-size), the generator
// blocks the encoder feeds, the adversarial and feature-matching weights,
// ADA, full-tune (no PTI, the generator trained too) and generator weights to
// start from instead of the prior. Its GANs also read train's --batch,
// --lr-discriminator, --r1-gamma, --r1-every, --ada-target and
// --collapse-steps, which the gan-avatar model shares.
struct DecoderTrainOptions {
  int decoder_steps = 0;
  double decoder_max_minutes = 0;  // stage 3's own wall-clock limit (0: none)
  int prior_steps = 1000;
  int pti_steps = 200;
  int pti_frames = 4;
  int decoder_resolution = 0;
  int projected_blocks = 5;
  double adversarial_weight = 0.05;
  double perceptual_weight = 0.1;
  bool decoder_ada = true;
  bool full_tune = false;
  std::string decoder_init;
};

// Stages 1 (canonical Gaussians and the triplane generator) and 2 (the
// attention deformation and the region loss), then stage 3.
struct GaussianStyleTrainOptions {
  double canonical_fraction = 0.25;  // the share of the steps in stage 1
  bool deform = true;           // stage 2; false trains stage 1 alone
  // Gaussians bound to the tracked mesh's triangles (beyond the paper; false:
  // the paper's deformation in canonical space). On by default: measured
  // 1.5 dB better on talking_static, as good on GRID (docs/benchmarks.md).
  bool mesh_riding = true;
  double region_weight = 1.0;   // stage 2's L1 on the eyes' and mouth's crops (0: none)
  // Stage 2: the share of training views drawn with frame 0's latent (the
  // one inference uses) instead of their own, so that the expression must
  // come from the tracked condition (0: the paper's, every view its own).
  double latent_dropout = 0;
  double ssim_weight = 0.2;     // loss = (1 - w) L1 + w (1 - SSIM)
  // The fraction of the training frames set aside as validation frames
  // (never trained on; the last ones, or every round(1 / validation)-th with
  // an interleaved hold-out), scored at each evaluation (none without
  // evaluations: eval_every 0); and, when `patience` > 0, stage 2 stops once
  // their score has not risen for that many evaluations. The held-out frames
  // play no part.
  double validation = 0;
  int patience = 0;
  // Adam's step for a rigid correction of each training view's tracked head
  // pose (radians and metres), learnt with the avatar; 0 keeps the tracked
  // poses. Held-out views keep theirs.
  double pose_lr = 0;
  // Training views per step, their losses averaged (0: one, or one per rank
  // of a data-parallel training).
  int views_per_step = 0;
  int init_gaussians = 20000;   // sampled on the tracked mesh
  int64_t max_gaussians = 40000;
  int densify_from = 300, densify_until = 3000, densify_every = 100;
  double grad_threshold = 0.0002;
  // Adam's steps of the Gaussians' rows (the networks': train's lr_network).
  double lr_means = 1.6e-4, lr_quats = 1e-3, lr_scales = 5e-3, lr_opacity = 5e-2, lr_features = 2.5e-3;
  DecoderTrainOptions decoder;  // stage 3

  // Its options alone, whichever model trains (stage 3's are checked with
  // the shared ones they go with, by TrainOptions::Check, when it trains).
  Status Check() const;
};

// By field name, stage 3's in a "decoder" object. Reading gives a field `j`
// lacks its default, and takes stage 3's from `j` itself when it has no
// "decoder" (the flat record written before the blocks).
nlohmann::json ToJson(const GaussianStyleTrainOptions& options);
void FromJson(const nlohmann::json& j, GaussianStyleTrainOptions* options);

// What a preset sets: each also an option of its own, train's common ones
// (device, training size, steps, cadence, networks, GANs) beside the model's.
struct GaussianStylePreset {
  std::string device;
  int resolution = 0, steps = 0;
  double max_minutes = 0;
  int eval_every = 0, preview_every = 0;
  int triplane_resolution = 0;
  double lr_network = 0;
  // Stage 3's GANs (the prior, the UV-conditioned discriminator) step as the
  // gan-avatar's do, in every preset.
  double lr_discriminator = 2.5e-4, r1_gamma = 1.0;
  int init_gaussians = 0;
  int64_t max_gaussians = 0;
  int densify_until = 0;
  double validation = 0;
  int patience = 0;
  int decoder_steps = 0, prior_steps = 0, pti_steps = 0;
};

// draft, standard or high; false for a name that is none.
bool FindGaussianStylePreset(const std::string& name, GaussianStylePreset* preset);

// Binds the options to their dotted keys (train.canonical_fraction, ...)
// and short flags. The full build's (register_options.cc): the LibTorch-only
// build has no command line.
void AddGaussianStyleOptions(OptionSet* options, GaussianStyleTrainOptions* gaussian_style);

}  // namespace headforge
