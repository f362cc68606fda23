// Training an avatar on a tracked workspace, for callers that do not use
// LibTorch (the train stage, the benches): options with presets, the run, and
// what it reports. The gaussian-style model's stages 1 (canonical Gaussians
// and the triplane generator) and 2 (the attention deformation and the
// region loss), and the gan-avatar model's appearance GAN, run here; see
// docs/avatar.md.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "avatar/model_table.h"
#include "avatar/train/dataset_options.h"
#include "core/fs.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct TrainOptions {
  std::string model{kGaussianStyle.name};
  // draft: two CPU cores, about 15 minutes; standard: one GPU; high: the
  // paper's scale. A preset fills only the options not given; the models
  // have presets of their own.
  std::string preset = "draft";
  std::string device = "cpu";   // cpu, or cuda (cuda:N) with a CUDA LibTorch
  int resolution = 256;         // the frames' longer side, pixels
  int steps = 6000;             // optimisation steps, one view each
  double max_minutes = 15;      // stop training at this wall time (0: no limit)
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
  double holdout = 0.2;         // the fraction of the frames never trained on
  std::string holdout_order = "auto";  // which: last, interleaved or auto (DatasetOptions)
  // gaussian-style: the fraction of the training frames set aside as
  // validation frames (never trained on; the last ones, or every
  // round(1 / validation)-th with an interleaved hold-out), scored at each
  // evaluation (none without evaluations: eval_every 0); and, when
  // `patience` > 0, stage 2 stops once their score has not risen for that
  // many evaluations. The held-out frames play no part.
  double validation = 0;
  int patience = 0;
  std::vector<std::string> holdout_cameras;  // cameras never trained on, scored with the held-out frames
  // The head masks trained and scored on (DatasetOptions::mask): ingest,
  // mesh, or auto (mesh for gaussian-style, which trains on tracked frames;
  // ingest for gan-avatar, whose views may see sides the tracker cannot).
  std::string mask = "auto";
  double mask_hair = 0.03;  // "mesh": metres the mask may reach beyond the scalp
  double mask_skin = 0.016;  // "mesh": ... and beyond the rest of the tracked mesh
  // gaussian-style: Adam's step for a rigid correction of each training
  // view's tracked head pose (radians and metres), learnt with the avatar;
  // 0 keeps the tracked poses. Held-out views keep theirs.
  double pose_lr = 0;
  // The mask `model` trains with under these options: ingest or mesh.
  std::string MaskFor(const AvatarModel& model_entry) const {
    return mask != "auto" ? mask : std::string(model_entry.default_mask);
  }
  int init_gaussians = 20000;   // sampled on the tracked mesh
  int64_t max_gaussians = 40000;
  int densify_from = 300, densify_until = 3000, densify_every = 100;
  double grad_threshold = 0.0002;
  double lr_network = 5e-4;     // Adam for the networks and latents (the paper: 1e-4)
  double lr_means = 1.6e-4, lr_quats = 1e-3, lr_scales = 5e-3, lr_opacity = 5e-2, lr_features = 2.5e-3;
  int feature_channels = 32;
  int triplane_resolution = 64;
  int latent_dim = 64;
  // gan-avatar: the volume render's longer side (--train-size is the
  // super-resolved output's; their ratio a power of two), views per batch,
  // the discriminator's step, R1's weight and interval, ADA's target and
  // the samples per ray (stratified, then importance).
  int render_resolution = 32;
  int batch = 4;
  int reconstruction_steps = 0;  // gan-avatar: the warm-up's steps before the adversarial ones
  double recon_weight = 1.0;     // gan-avatar: the reconstruction's weight after the warm-up (0: none)
  int adversarial_ramp = 300;    // gan-avatar: steps over which the adversarial loss comes in
  double lr_discriminator = 2e-3;
  double r1_gamma = 0.2;
  int r1_every = 4;
  double ada_target = 0.6;
  // Discriminator steps in a row telling every real image from every
  // generated one before a mode-collapse warning (0: never).
  int collapse_steps = 200;
  int coarse_samples = 24, fine_samples = 24;
  // gan-avatar's expression mapping: renders sampled and tracked, steps,
  // loss ("image": photometric, the paper's; "latent": the ablation), and
  // the landmark model that reads the renders.
  int mapping_samples = 256;
  int mapping_steps = 300;
  std::string mapping_loss = "image";
  // Which latents the mapping's renders come from: "random" (z ~ N(0, I),
  // the paper's) or "frames" (the reconstruction warm-up's latents of the
  // training frames, then blends of two).
  std::string mapping_latents = "random";
  std::string landmark_model;
  // gan-avatar: a folder where the GAN was trained already (headforge-train's
  // output for this workspace's pack, on a GPU machine): its generator is
  // taken and only the expression mapping trains; the options that shape the
  // model and its views come from that folder's config.json.
  std::string generator_from;
  // gaussian-style's stage 3, the StyleGAN decoder: its steps (0: no stage
  // 3), the personal prior's steps (the generator trained on the frames),
  // PTI's steps (each half) and frames, the decoder's side (0: --train-size),
  // the generator blocks the encoder feeds, the adversarial and
  // feature-matching weights, ADA, full-tune (no PTI, the generator trained
  // too) and generator weights to start from instead of the prior.
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
  int log_every = 50, eval_every = 1000, preview_every = 1000, checkpoint_every = 250;
  int seed = 0;

  Status Check() const;
};

// Every option by its field name, for a training pack's record of the run it
// is for; a field the JSON lacks keeps its default.
nlohmann::json ToJson(const TrainOptions& options);
TrainOptions TrainOptionsFromJson(const nlohmann::json& j);

void AddTrainOptions(OptionSet* options, TrainOptions* train);
// Gives the preset's values to the options `parsed` says nobody set.
Status ApplyTrainPreset(const OptionSet& parsed, TrainOptions* train);
// The frames a preset trains on at most (ingest's --select in `headforge
// run`): draft 300, standard 2000, high 6000; 0 for a name that is none.
int PresetFrameBudget(const std::string& preset);

// Fails when the ingested capture in `workspace` has too few frames for
// either model to train on kFewestTrainingFrames besides those held out
// (whichever way they are chosen); Ok when it has enough or cannot be read.
Status CheckEnoughFramesToTrain(const fs::path& workspace, double holdout);

// The model `--model auto` (the train stage's default) trains on an aligned
// workspace: gan-avatar when its cameras are several, or its views spread
// kWalkAroundSpreadDeg or more round the head (a 360-degree or multi-view
// capture), else gaussian-style (one fixed camera, or one that moves a
// little); `why` says which in a few words.
Status ChooseModel(const fs::path& workspace, std::string* model, std::string* why);

struct TrainSummary {
  int steps = 0, resumed_from = 0;
  double seconds = 0;           // training time, over every attempt
  int64_t gaussians = 0;
  int test_views = 0;
  // Held-out views, background one colour in both images: over the head
  // mask, and over the whole frame.
  double psnr_masked = 0, ssim_masked = 0, psnr_full = 0, ssim_full = 0, l1_masked = 0;
  double train_psnr_masked = 0;  // every 10th training view, with its own frame latent
  std::vector<std::string> outputs;  // relative to the output folder
  std::string note;                  // what the user should know of the run ("" or a clause)
  std::string OneLine() const;
};

// Trains on `workspace` (ingest, calibrate, align and track done) into
// `out_dir`, which holds its checkpoint between attempts: a run that finds
// one continues from it. Writes model.pt, config.json, stats.jsonl,
// eval.json, previews/ and held_out/.
Status RunTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                const fs::path& out_dir, Progress* progress, TrainSummary* summary);

// The same run in two halves, for a GPU machine without the rest of the
// stack: WriteTrainPack reads the workspace's views as RunTrain would and
// writes them with `options` into one file (avatar/train/dataset_pack.h);
// TrainFromPack, which needs LibTorch alone (the headforge-train program),
// trains on it into `out_dir` with the same result as RunTrain. `settings`
// ("field=value", TrainOptions' field names: device=cuda, max_minutes=9)
// replace the pack's options. For the gan-avatar model the pack trains the
// GAN alone (the expression mapping tracks the GAN's renders, which needs
// the full build): `headforge train --generator-from DIR` adds the mapping
// on the workspace's machine.
Status WriteTrainPack(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                      const fs::path& pack);
Status TrainFromPack(const fs::path& pack, const std::vector<std::string>& settings, const fs::path& out_dir,
                     Progress* progress, TrainSummary* summary);

}  // namespace headforge
