// The gaussian-style model's options on the command line and in config
// files (train.*), with their short flags; the full build's alone.
#include "avatar/gaussian_style/options.h"
#include "core/options.h"

namespace headforge {

void AddGaussianStyleOptions(OptionSet* o, GaussianStyleTrainOptions* g) {
  o->Add("train.canonical_fraction", &g->canonical_fraction,
         "The share of the steps in stage 1 (canonical Gaussians and triplanes) before stage 2 (deformation).",
         "canonical-fraction");
  o->Add("train.deform", &g->deform, "Train stage 2, the attention deformation (false: stage 1 only).", "deform");
  o->Add("train.mesh_riding", &g->mesh_riding,
         "Bind the Gaussians to the tracked mesh's triangles, which the tracked expressions move; the network "
         "predicts changes in their frames. --mesh-riding=false: the paper's deformation in canonical space.",
         "mesh-riding");
  o->Add("train.latent_dropout", &g->latent_dropout,
         "Stage 2: the share of training views drawn with frame 0's latent, the one held-out frames and render use, "
         "instead of their own (0: each its own, as the paper).",
         "latent-dropout");
  o->Add("train.region_weight", &g->region_weight, "Weight of stage 2's L1 on the eyes' and mouth's crops (0: none).",
         "region-weight");
  o->Add("train.ssim_weight", &g->ssim_weight, "Loss = (1 - w) L1 + w (1 - SSIM).", "ssim-weight");
  o->Add("train.validation", &g->validation,
         "gaussian-style: the fraction of the training frames set aside to choose when training stops (never "
         "trained on; the last ones, or interleaved like the hold-out); scored at each --eval-every. 0, or "
         "--eval-every 0: none.",
         "validation");
  o->Add("train.patience", &g->patience,
         "gaussian-style: stop stage 2 once the validation frames' score has not risen for this many evaluations "
         "(0: train every step). Without validation frames it has nothing to wait on and training runs its steps.",
         "patience");
  o->Add("train.pose_lr", &g->pose_lr,
         "gaussian-style: Adam's step of a rigid correction of each training view's tracked head pose (radians, "
         "metres), learnt with the avatar where the tracked poses are a little off; 0 keeps them. Held-out views "
         "keep their tracked poses.",
         "pose-lr");
  o->Add("train.views_per_step", &g->views_per_step,
         "gaussian-style: training views in each step of stages 1-2, their losses averaged (0: one, or one per rank "
         "when headforge-train runs data-parallel under torchrun or srun: docs/cluster.md).",
         "views-per-step");
  o->Add("train.init_gaussians", &g->init_gaussians, "Gaussians sampled on the tracked mesh to start with.",
         "init-gaussians");
  o->Add("train.max_gaussians", &g->max_gaussians, "Densification adds no more beyond this count.", "max-gaussians");
  o->Add("train.densify_from", &g->densify_from, "First step that densifies.", "densify-from");
  o->Add("train.densify_until", &g->densify_until, "Last step that densifies.", "densify-until");
  o->Add("train.densify_every", &g->densify_every, "Steps between densifications.", "densify-every");
  o->Add("train.grad_threshold", &g->grad_threshold,
         "Mean screen-space gradient above which a Gaussian is cloned or split.", "grad-threshold");
  o->Add("train.lr_means", &g->lr_means, "Adam step of the positions (times the extent), decaying to 1%.", "lr-means");
  o->Add("train.lr_quats", &g->lr_quats, "Adam step of the rotations.", "lr-quats");
  o->Add("train.lr_scales", &g->lr_scales, "Adam step of the log-scales.", "lr-scales");
  o->Add("train.lr_opacity", &g->lr_opacity, "Adam step of the opacity logits.", "lr-opacity");
  o->Add("train.lr_features", &g->lr_features, "Adam step of the Gaussians' features.", "lr-features");
  o->Add("train.decoder_steps", &g->decoder.decoder_steps,
         "gaussian-style: steps of stage 3, the StyleGAN decoder that turns the splatted 32-channel features into "
         "the image (0: none; the image is the splatted RGB).",
         "decoder-steps");
  o->Add("train.decoder_max_minutes", &g->decoder.decoder_max_minutes,
         "gaussian-style: stop stage 3 after this many minutes (0: no limit). Its own limit: --max-minutes stops "
         "stages 1-2, and stage 3's phases are long (its prior first).",
         "decoder-max-minutes");
  o->Add("train.prior_steps", &g->decoder.prior_steps,
         "gaussian-style stage 3: steps training the decoder's generator on the training frames (a personal prior in "
         "place of pretrained FFHQ weights) before PTI.",
         "prior-steps");
  o->Add("train.pti_steps", &g->decoder.pti_steps,
         "gaussian-style stage 3: PTI's steps inverting the extreme-pose frames, and as many fine-tuning the "
         "generator.",
         "pti-steps");
  o->Add("train.pti_frames", &g->decoder.pti_frames,
         "gaussian-style stage 3: the frames of the most extreme head poses PTI uses.", "pti-frames");
  o->Add("train.decoder_resolution", &g->decoder.decoder_resolution,
         "gaussian-style stage 3: the decoder's square side, a power of two (0: --train-size).", "decoder-resolution");
  o->Add("train.projected_blocks", &g->decoder.projected_blocks,
         "gaussian-style stage 3: generator blocks (4, 8, 16, ... px) the encoder's features are fused into.",
         "projected-blocks");
  o->Add("train.adversarial_weight", &g->decoder.adversarial_weight,
         "gaussian-style stage 3: weight of the UV-conditioned adversarial loss (0: no discriminator).",
         "adversarial-weight");
  o->Add("train.perceptual_weight", &g->decoder.perceptual_weight,
         "gaussian-style stage 3: weight of the discriminator feature matching that stands in for LPIPS.",
         "perceptual-weight");
  o->Add("train.decoder_ada", &g->decoder.decoder_ada,
         "gaussian-style stage 3: adaptive augmentation of the discriminator's inputs.", "decoder-ada");
  o->Add("train.full_tune", &g->decoder.full_tune,
         "gaussian-style stage 3: no PTI, and the generator trained with the rest (the paper's full-tune ablation).",
         "full-tune");
  o->Add("train.decoder_init", &g->decoder.decoder_init,
         "gaussian-style stage 3: a .safetensors file of generator weights to start from instead of the personal "
         "prior (layout in docs/avatar.md).",
         "decoder-init");
}

}  // namespace headforge
