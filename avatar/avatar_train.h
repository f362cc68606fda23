// Training an avatar on a tracked workspace, for callers that do not use
// LibTorch (the train stage, the benches): options with presets, the run, and
// what it reports. The gaussian-style model's stages 1 (canonical Gaussians
// and the triplane generator) and 2 (the attention deformation and the
// region loss), and the gan-avatar model's appearance GAN, run here; see
// docs/avatar.md.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "avatar/gan_avatar/options.h"
#include "avatar/gaussian_style/options.h"
#include "avatar/model_table.h"
#include "avatar/train/dataset_options.h"
#include "core/fs.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

class Collective;  // avatar/train/loop.h: the ranks of a data-parallel training

// The training loop's length and cadence (avatar/train/loop.h's
// LoopOptions, made by TrainLoopOptions in train_loop_options.h), every
// model's and stage's alike.
struct TrainLoopSettings {
  int steps = 6000;             // optimisation steps, one view each
  double max_minutes = 15;      // stop training at this wall time (0: no limit)
  int log_every = 50, eval_every = 1000, preview_every = 1000, checkpoint_every = 250;

  Status Check() const;
};

// The views training loads: DatasetOptions' defaults but --mask auto (each
// model's own masks, or hull: TrainOptions::DataFor).
inline DatasetOptions TrainingDatasetOptions() {
  DatasetOptions data;
  data.mask = "auto";
  return data;
}

// train's options: the common part (the model, the preset, the device, the
// seed, and the options both models read), the views, the loop, and one
// block per model, each in its folder. A field's name is its dotted key's
// last part (train.lr_network; data.resolution is train.resolution) and its
// name in a record (ToJson).
struct TrainOptions {
  std::string model{kGaussianStyle.name};
  // draft: two CPU cores, about 15 minutes; standard: one GPU; high: the
  // paper's scale. A preset fills only the options not given; the models
  // have presets of their own.
  std::string preset = "draft";
  std::string device = "cpu";   // cpu, or cuda (cuda:N) with a CUDA LibTorch
  DatasetOptions data = TrainingDatasetOptions();
  TrainLoopSettings loop;
  // Both models' networks: Adam's step for the networks and latents (the
  // paper: 1e-4), and their triplane generator's shape.
  double lr_network = 5e-4;
  int feature_channels = 32;
  int triplane_resolution = 64;
  int latent_dim = 64;
  // Both models' GANs (the gan-avatar model's; gaussian-style's stage 3, its
  // prior and its UV-conditioned discriminator): views per batch, the
  // discriminator's step, R1's weight and interval, ADA's target, and the
  // discriminator steps in a row telling every real image from every
  // generated one before a mode-collapse warning (0: never).
  int batch = 4;
  double lr_discriminator = 2e-3;
  double r1_gamma = 0.2;
  int r1_every = 4;
  double ada_target = 0.6;
  int collapse_steps = 200;
  GaussianStyleTrainOptions gaussian_style;
  GanAvatarTrainOptions gan_avatar;
  int seed = 0;
  // The ranks of a data-parallel training (avatar/train/distributed.h), not
  // an option: set by the program that connected them. Null: one process.
  Collective* collective = nullptr;

  // The views as `model_entry` loads them: `data` with the model's own mask
  // for --mask auto (which the loader resolves by the capture).
  DatasetOptions DataFor(const AvatarModel& model_entry) const {
    DatasetOptions resolved = data;
    resolved.auto_mask = std::string(model_entry.default_mask);
    return resolved;
  }

  // Every part's checks, and those of the parts together (the render's size
  // against the training size, stage 3's and the gan-avatar's GANs).
  Status Check() const;
};

// The options by their field names in blocks: the common part at the top,
// then "data", "loop" and the block of the model `options.model` names,
// under its folder's name (AvatarModel::folder; none for a name that is
// none). A training pack's record of the run it is for, and a trained
// model's config.json's "options". Reading takes a block's fields from the
// top when the block is missing, so that the flat record written before the
// blocks (every field at the top) still reads; a field the JSON lacks keeps
// its default.
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
  // Stopped by its time limit, its checkpoint kept with the model: train
  // --extend with a longer --max-minutes goes on from it.
  bool extendable = false;
  std::string OneLine() const;
};

// The processes of one data-parallel `headforge train` (every rank runs the
// command on the workspace, started by torchrun or srun), connected through
// LibTorch's c10d (avatar/train/distributed.h). Rank 0 runs the train stage
// as one process does, holding the workspace; it tells the others whether
// it trains (Tell), and they (Hear) train the gaussian-style model's stages
// 1-2 beside it, writing nothing (FollowTrain).
class TrainRanks {
 public:
  ~TrainRanks();
  // `mode` "auto" (torchrun's or srun's variables; docs/cluster.md) or
  // "off"; `*ranks` stays null for one process.
  static Status Join(const std::string& mode, double timeout_s, std::unique_ptr<TrainRanks>* ranks);
  int rank() const;
  int world() const;
  // Rank 0, once: whether it trains (before its first step) or not (the
  // stage up to date, refused or failed before training).
  Status Tell(bool training);
  bool told() const { return told_; }
  // A rank above 0: rank 0's word.
  Status Hear(bool* training);
  Collective* collective();

 private:
  struct Impl;
  TrainRanks() = default;
  std::unique_ptr<Impl> impl_;
  bool told_ = false;
};

// Trains on `workspace` (ingest, calibrate, align and track done) into
// `out_dir`, which holds its checkpoint between attempts: a run that finds
// one continues from it. Writes model.pt, config.json, stats.jsonl,
// eval.json, previews/ and held_out/. With `ranks` (rank 0 of a
// data-parallel run) the gaussian-style model's stages 1-2 are trained with
// the other ranks.
Status RunTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                const fs::path& out_dir, Progress* progress, TrainSummary* summary, TrainRanks* ranks = nullptr);
// A rank above 0 of a data-parallel `headforge train`, once rank 0 has said
// it trains (TrainRanks::Hear): trains stages 1-2 beside it on the same
// views, reading rank 0's `out_dir` (its checkpoint, on a resume) and
// writing nothing. `*trained`: true when it did.
Status FollowTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                   const fs::path& out_dir, TrainRanks* ranks, bool* trained);

// The same run in two halves, for a GPU machine without the rest of the
// stack: WriteTrainPack reads the workspace's views as RunTrain would and
// writes them with `options` into one file (avatar/train/dataset_pack.h);
// TrainFromPack, which needs LibTorch alone (the headforge-train program),
// trains on it into `out_dir` with the same result as RunTrain. `settings`
// ("field=value", by the field's name in whichever block: device=cuda,
// max_minutes=9, decoder_steps=0)
// replace the pack's options. For the gan-avatar model the pack trains the
// GAN alone (the expression mapping tracks the GAN's renders, which needs
// the full build): `headforge train --generator-from DIR` adds the mapping
// on the workspace's machine.
Status WriteTrainPack(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                      const fs::path& pack);
// With `collective` (several ranks, each running TrainFromPack on the same
// pack and out_dir): the gaussian-style model's stages 1-2 are trained
// data-parallel, and rank 0 alone writes out_dir and trains stage 3.
Status TrainFromPack(const fs::path& pack, const std::vector<std::string>& settings, const fs::path& out_dir,
                     Progress* progress, TrainSummary* summary, Collective* collective = nullptr);

}  // namespace headforge
