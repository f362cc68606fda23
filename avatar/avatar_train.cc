#include "avatar/avatar_train.h"

#include <torch/torch.h>

#include <algorithm>

#include "avatar/gan_avatar/render_expressions.h"
#include "avatar/gan_avatar/trainer.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/dataset_pack.h"
#include "avatar/train/distributed.h"
#include "avatar/train/loop.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/paths.h"
#include "reconstruction/tracking_io.h"

namespace headforge {

// A long recording's frames, chosen by ingest for coverage: draft sees each
// of its 300 about nine times in its 15 minutes (2 600 steps measured);
// standard and high, the scale of the monocular captures published avatars
// train on (one to four minutes at 25 fps).
int PresetFrameBudget(const std::string& preset) {
  if (preset == "draft") return 300;
  if (preset == "standard") return 2000;
  if (preset == "high") return 6000;
  return 0;
}

void AddTrainOptions(OptionSet* o, TrainOptions* t) {
  std::string models;
  for (const AvatarModel& m : kAvatarModels) models += " " + m.Name() + ": " + std::string(m.summary) + ".";
  o->Add("train.model", &t->model,
         "Avatar model." + models + " The train stage's auto chooses " + kGaussianStyle.Name() +
             " for every capture the tracker read (one camera, a walk-around, a rig), " + kGanAvatar.Name() +
             " when it found the face in no frame.",
         "model");
  o->Add("train.preset", &t->preset,
         "draft (2 CPU cores, 256 px, within 15 min), standard (one GPU, 512 px), high (the paper's scale); it sets "
         "the defaults of the options below that are not given.",
         "preset");
  o->Add("train.device", &t->device, "cpu, or cuda (cuda:N) in a build against a LibTorch with CUDA.", "device",
         OptionSet::Effect::kRuntime);
  o->Add("train.resolution", &t->data.resolution, "The frames' longer side while training, pixels.", "train-size");
  o->AddOldFlag("train.resolution", "resolution");
  o->Add("train.holdout", &t->data.holdout, "The fraction of the frames held out for evaluation.", "holdout");
  o->Add("train.holdout_order", &t->data.holdout_order,
         "Which frames: last (the last ones), interleaved (every round(1/holdout)-th: views between training views) "
         "or auto (interleaved for one camera whose views circle the head 120 degrees or more, else last).",
         "holdout-order");
  o->Add("train.holdout_cameras", &t->data.holdout_cameras,
         "Cameras held out whole (every frame of theirs scored, none trained on), comma-separated.",
         "holdout-cameras");
  o->Add("train.mask", &t->data.mask,
         "The head masks trained and scored on: ingest (the workspace's masks), mesh (the workspace's masks cut to "
         "the tracked mesh's silhouette, grown by --mask-hair over the scalp and --mask-skin elsewhere: background "
         "of the skin's colour beside the head is left out), hull (one camera carried round a still head: every "
         "view's mask made to agree with the others', the shape most views' masks hold seen from each view, so "
         "that a mask that took background or lost the face in a few views is put right) or auto (hull for a "
         "camera carried round a still head; else mesh for gaussian-style, ingest for gan-avatar).",
         "mask");
  o->Add("train.mask_hair", &t->data.mask_hair,
         "--mask mesh: how far (metres) the mask may reach beyond the tracked scalp, for hair; raise it for big hair.",
         "mask-hair");
  o->Add("train.mask_skin", &t->data.mask_skin,
         "--mask mesh: how far (metres) the mask may reach beyond the rest of the tracked mesh (face, ears, neck), "
         "for the tracking's error.",
         "mask-skin");
  o->Add("train.steps", &t->loop.steps, "Optimisation steps (one view each), both stages.", "steps");
  o->Add("train.max_minutes", &t->loop.max_minutes, "Stop training after this many minutes (0: no limit).",
         "max-minutes");
  o->Add("train.log_every", &t->loop.log_every, "Steps between lines of stats.jsonl.", "log-every");
  o->Add("train.eval_every", &t->loop.eval_every, "Steps between held-out evaluations (0: only at the end).",
         "eval-every");
  o->Add("train.preview_every", &t->loop.preview_every, "Steps between preview images (0: none).", "preview-every");
  o->Add("train.checkpoint_every", &t->loop.checkpoint_every,
         "Steps between checkpoints; an interrupted run (Ctrl-C, a kill) resumes from the last.", "checkpoint-every",
         OptionSet::Effect::kRuntime);
  o->Add("train.lr_network", &t->lr_network, "Adam step of the networks and frame latents.", "lr-network");
  o->Add("train.feature_channels", &t->feature_channels, "Feature channels per Gaussian (the first three RGB).",
         "feature-channels");
  o->Add("train.triplane_resolution", &t->triplane_resolution, "Side of each triplane, a power of two.",
         "triplane-resolution");
  o->Add("train.latent_dim", &t->latent_dim, "Size of each frame's latent.", "latent-dim");
  o->Add("train.batch", &t->batch, "gan-avatar, and stage 3's prior: real and generated views per step.", "batch");
  o->Add("train.lr_discriminator", &t->lr_discriminator, "gan-avatar: Adam step of the discriminator; gaussian-style stage 3: of its prior's generator and "
         "discriminator and of the UV-conditioned discriminator.",
         "lr-discriminator");
  o->Add("train.r1_gamma", &t->r1_gamma, "gan-avatar and stage 3: weight of the R1 penalty on the real images (0: none).",
         "r1-gamma");
  o->Add("train.r1_every", &t->r1_every, "gan-avatar: steps between R1 penalties (lazy regularisation).", "r1-every");
  o->Add("train.ada_target", &t->ada_target,
         "gan-avatar: the adaptive augmentation raises its probability while E[sign D(real)] is above this.",
         "ada-target");
  o->Add("train.collapse_steps", &t->collapse_steps,
         "gan-avatar and stage 3: discriminator steps in a row telling every real image from every generated one "
         "before a mode-collapse warning in the log and stats.jsonl (0: never).",
         "collapse-steps");
  AddGaussianStyleOptions(o, &t->gaussian_style);
  AddGanAvatarOptions(o, &t->gan_avatar);
  o->Add("train.seed", &t->seed, "Seed of the initial Gaussians, the networks, the view order and backgrounds.",
         "train-seed");
}

Status ApplyTrainPreset(const OptionSet& parsed, TrainOptions* t) {
  auto fill = [&](const char* key, auto* field, auto value) {
    if (!parsed.WasGiven(key)) *field = value;
  };
  auto unknown = [&] {
    return Status::InvalidArgument("train: --preset must be draft, standard or high, not '" + t->preset + "'");
  };
  if (kGanAvatar.Is(t->model)) {
    GanAvatarPreset p;
    if (!FindGanAvatarPreset(t->preset, &p)) return unknown();
    fill("train.device", &t->device, p.device);
    fill("train.resolution", &t->data.resolution, p.resolution);
    fill("train.render_resolution", &t->gan_avatar.render_resolution, p.render_resolution);
    fill("train.steps", &t->loop.steps, p.steps);
    fill("train.max_minutes", &t->loop.max_minutes, p.max_minutes);
    fill("train.triplane_resolution", &t->triplane_resolution, p.triplane_resolution);
    fill("train.batch", &t->batch, p.batch);
    fill("train.reconstruction_steps", &t->gan_avatar.reconstruction_steps, p.reconstruction_steps);
    fill("train.lr_network", &t->lr_network, p.lr_network);
    fill("train.lr_discriminator", &t->lr_discriminator, p.lr_discriminator);
    fill("train.r1_gamma", &t->r1_gamma, p.r1_gamma);
    fill("train.eval_every", &t->loop.eval_every, p.eval_every);
    fill("train.preview_every", &t->loop.preview_every, p.preview_every);
    return Status::Ok();
  }
  GaussianStylePreset p;
  if (!FindGaussianStylePreset(t->preset, &p)) return unknown();
  GaussianStyleTrainOptions& g = t->gaussian_style;
  fill("train.device", &t->device, p.device);
  fill("train.resolution", &t->data.resolution, p.resolution);
  fill("train.steps", &t->loop.steps, p.steps);
  fill("train.max_minutes", &t->loop.max_minutes, p.max_minutes);
  fill("train.init_gaussians", &g.init_gaussians, p.init_gaussians);
  fill("train.max_gaussians", &g.max_gaussians, p.max_gaussians);
  fill("train.densify_until", &g.densify_until, p.densify_until);
  fill("train.triplane_resolution", &t->triplane_resolution, p.triplane_resolution);
  fill("train.lr_network", &t->lr_network, p.lr_network);
  fill("train.eval_every", &t->loop.eval_every, p.eval_every);
  fill("train.preview_every", &t->loop.preview_every, p.preview_every);
  fill("train.lr_discriminator", &t->lr_discriminator, p.lr_discriminator);
  fill("train.r1_gamma", &t->r1_gamma, p.r1_gamma);
  fill("train.decoder_steps", &g.decoder.decoder_steps, p.decoder_steps);
  fill("train.prior_steps", &g.decoder.prior_steps, p.prior_steps);
  fill("train.pti_steps", &g.decoder.pti_steps, p.pti_steps);
  fill("train.validation", &g.validation, p.validation);
  fill("train.patience", &g.patience, p.patience);
  return Status::Ok();
}

Status CheckEnoughFramesToTrain(const fs::path& workspace, double holdout) {
  IngestedCapture capture;
  if (!ReadIngestedCapture(workspace, &capture).ok()) return Status::Ok();  // the stages say what is wrong
  auto trainable = [&](int frames) {
    return frames - std::min(HeldOutFrames(frames, holdout, false), HeldOutFrames(frames, holdout, true));
  };
  const int frames = capture.num_frames();
  if (trainable(frames) >= kFewestTrainingFrames) return Status::Ok();
  int needed = frames + 1;
  while (trainable(needed) < kFewestTrainingFrames) ++needed;
  return Status::DataError("train: ingest made " + std::to_string(frames) + (frames == 1 ? " frame" : " frames") +
                           "; an avatar needs at least " + std::to_string(needed) + " (" +
                           std::to_string(kFewestTrainingFrames) + " to train on besides those it holds out). " +
                           "Ingest a longer video (or more of it: --fps, --max-frames, --select), or give --until "
                           "track to stop before train");
}

Status ChooseModel(const fs::path& workspace, std::string* model, std::string* why) {
  CameraSet cameras;
  HF_RETURN_IF_ERROR(CameraSet::Read(workspace / "cameras_head.json", &cameras)
                         .WithContext("train: --model auto reads the aligned cameras (run headforge align)"));
  // Measured (docs/benchmarks/capture_360.md): gaussian-style on every kind
  // of capture the tracker can read, a walk-around and a 20-camera dome
  // included (29.7 and 21.5 dB held out against gan-avatar's 21.6 and 19.1);
  // gan-avatar where the tracker found the face in no frame, since it trains
  // without tracked expressions.
  const double spread = cameras.AzimuthSpreadDeg();
  char text[200];
  if (cameras.cameras.size() > 1)
    std::snprintf(text, sizeof(text), "%zu cameras: a multi-view capture", cameras.cameras.size());
  else if (cameras.WalksRoundTheHead())
    std::snprintf(text, sizeof(text), "one camera whose views spread %.0f deg round the head", spread);
  else
    std::snprintf(text, sizeof(text), "one camera, its views within %.0f deg of one another (%s cameras)", spread,
                  cameras.mode.c_str());
  *model = kGaussianStyle.Name();
  *why = text;
  TrackingFile tracking;
  if (ReadTracking(workspace / "tracking.json", &tracking).ok() && !tracking.frames.empty() &&
      std::all_of(tracking.frames.begin(), tracking.frames.end(),
                  [](const TrackedFrame& f) { return f.interpolated; })) {
    *model = kGanAvatar.Name();
    *why += "; the tracker found the face in no frame";
  }
  return Status::Ok();
}

namespace {

// The workspace's views as the run of `options` trains on them (with the UV
// maps stage 3's discriminator needs).
Status LoadTrainingData(const TrainOptions& options, const fs::path& workspace, const FaceModel& model,
                        AvatarDataset* data) {
  DatasetOptions loading = options.DataFor(*FindAvatarModel(options.model));
  const DecoderTrainOptions& decoder = options.gaussian_style.decoder;
  if (kGaussianStyle.Is(options.model) && decoder.decoder_steps > 0 && decoder.adversarial_weight > 0)
    loading.uv_map_side = decoder.decoder_resolution > 0 ? decoder.decoder_resolution : options.data.resolution;
  HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, model, loading, data).WithContext("train"));
  HF_LOG(Info) << "train: " << data->train.size() << " training and " << data->test.size() << " held-out views at "
               << data->width << "x" << data->height << " (held out: " << data->HeldOutText() << ")";
  if (data->one_state)
    HF_LOG(Info) << "train: a still head one camera goes round: every view carries one expression (the median of "
                 << data->one_state_facing_views << " views that face the face) and frame 0's latent";
  if (data->mask == "hull")
    HF_LOG(Info) << "train: masks made to agree across the views (--mask hull): " << data->hull_stats.agreeing << " of "
                 << data->hull_stats.views << " training views' masks agreed on the shape; "
                 << data->hull_stats.replaced << " view(s) whose mask did not took its silhouette whole"
                 << (data->hull_stats.dropped_points > 0
                         ? "; " + std::to_string(data->hull_stats.dropped_points) +
                               " grid points apart from the head dropped"
                         : std::string());
  return Status::Ok();
}

}  // namespace

namespace {

// --generator-from DIR: the options DIR's training recorded, with this
// command's for what only the mapping and this machine use.
Status AdoptRecordedOptions(const TrainOptions& options, TrainOptions* resolved) {
  const fs::path dir = options.gan_avatar.generator_from;
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadJson(dir / "config.json", &config)
                         .WithContext("train: --generator-from takes the folder headforge-train (or train) wrote"));
  if (!kGanAvatar.Is(config.value("model", "")) || !config.contains("options"))
    return Status::InvalidArgument("train: --generator-from " + dir.string() +
                                   " holds no gan-avatar training of this version (its config.json records no "
                                   "options); train it again with this version's headforge-train");
  try {
    *resolved = TrainOptionsFromJson(config.at("options"));
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(dir.string() + "/config.json: its options do not read (" + e.what() + ")");
  }
  resolved->device = options.device;
  GanAvatarTrainOptions& gan = resolved->gan_avatar;
  gan.mapping_samples = options.gan_avatar.mapping_samples;
  gan.mapping_steps = options.gan_avatar.mapping_steps;
  gan.mapping_loss = options.gan_avatar.mapping_loss;
  gan.mapping_latents = options.gan_avatar.mapping_latents;
  gan.landmark_model = options.gan_avatar.landmark_model;
  resolved->loop.log_every = options.loop.log_every;
  resolved->loop.checkpoint_every = options.loop.checkpoint_every;
  gan.generator_from = options.gan_avatar.generator_from;
  HF_LOG(Info) << "train: the GAN of " << dir.string() << " (resolution " << resolved->data.resolution << ", render "
               << gan.render_resolution << ", preset " << resolved->preset
               << "): its recorded options shape the model and the views";
  return resolved->Check();
}

}  // namespace

struct TrainRanks::Impl {
  std::unique_ptr<ProcessGroup> group;
};

TrainRanks::~TrainRanks() = default;

Status TrainRanks::Join(const std::string& mode, double timeout_s, std::unique_ptr<TrainRanks>* ranks) {
  ranks->reset();
  DistributedSetup setup;
  HF_RETURN_IF_ERROR(ReadDistributedSetup(mode, &setup));
  if (setup.world <= 1) return Status::Ok();
  HF_LOG(Info) << "train: rank " << setup.rank << " of " << setup.world << " (" << setup.source << "), meeting at "
               << setup.address << ":" << setup.port;
  std::unique_ptr<TrainRanks> joined(new TrainRanks());
  joined->impl_ = std::make_unique<Impl>();
  HF_RETURN_IF_ERROR(ProcessGroup::Connect(setup, timeout_s, &joined->impl_->group));
  *ranks = std::move(joined);
  return Status::Ok();
}

int TrainRanks::rank() const { return impl_->group->rank(); }
int TrainRanks::world() const { return impl_->group->world(); }
Collective* TrainRanks::collective() { return impl_->group.get(); }

Status TrainRanks::Tell(bool training) {
  if (told_ || rank() != 0) return Status::Internal("train: only rank 0 tells, once, whether it trains");
  told_ = true;
  std::vector<uint8_t> word = {uint8_t(training)};
  return impl_->group->AnyOf(&word);
}

Status TrainRanks::Hear(bool* training) {
  if (rank() == 0) return Status::Internal("train: rank 0 tells, it does not hear");
  std::vector<uint8_t> word = {0};
  HF_RETURN_IF_ERROR(impl_->group->AnyOf(&word));
  *training = word[0] != 0;
  return Status::Ok();
}

Status RunTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                const fs::path& out_dir, Progress* progress, TrainSummary* summary, TrainRanks* ranks) {
  UseTensorThreads();
  HF_RETURN_IF_ERROR(options.Check());
  // Ranks of torchrun's that were not joined (--distributed off) would each
  // train the workspace alone, and meet at its lock.
  if (DistributedSetup setup;
      ranks == nullptr && ReadDistributedSetup("auto", &setup).ok() && setup.source == "torchrun" && setup.world > 1)
    return Status::InvalidArgument(
        "train: RANK and WORLD_SIZE=" + std::to_string(setup.world) + " ask for data-parallel training, which "
        "headforge train and headforge run do when every rank runs them (--distributed auto), or headforge-train on a "
        "training pack (docs/cluster.md); unset RANK and WORLD_SIZE to train here in one process");
  if (ranks != nullptr) HF_RETURN_IF_ERROR(CheckDataParallelModel(options.model, "headforge train"));
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  TrainOptions resolved = options;
  if (!options.gan_avatar.generator_from.empty()) HF_RETURN_IF_ERROR(AdoptRecordedOptions(options, &resolved));
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrainingData(resolved, workspace, model, &data));
  if (ranks != nullptr) {
    resolved.collective = ranks->collective();
    HF_RETURN_IF_ERROR(ranks->Tell(true));
  }
  if (!kGanAvatar.Is(resolved.model)) return TrainGaussianStyleRun(resolved, data, out_dir, progress, summary);
  if (resolved.gan_avatar.landmark_model.empty()) resolved.gan_avatar.landmark_model = DefaultLandmarkModel();
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(workspace / "tracking.json", &tracking));
  const ImageTracker track_images = [&](const torch::Tensor& images, const std::vector<SplatCamera>& cameras,
                                        Progress* p, RenderExpressions* out) {
    RenderExpressionOptions reading;
    reading.landmark_model = resolved.gan_avatar.landmark_model;
    reading.threads = TensorThreads();
    return EstimateImageExpressions(images, cameras, model, tracking, reading, p, out);
  };
  return TrainGanAvatar(resolved, data, track_images, out_dir, progress, summary);
}

Status FollowTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                   const fs::path& out_dir, TrainRanks* ranks, bool* trained) {
  UseTensorThreads();
  *trained = false;
  HF_RETURN_IF_ERROR(options.Check());
  HF_RETURN_IF_ERROR(CheckDataParallelModel(options.model, "headforge train"));
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrainingData(options, workspace, model, &data));
  TrainOptions resolved = options;
  resolved.collective = ranks->collective();
  NullProgress quiet;
  TrainSummary summary;
  HF_RETURN_IF_ERROR(TrainGaussianStyleRun(resolved, data, out_dir, &quiet, &summary));
  *trained = true;
  return Status::Ok();
}

Status WriteTrainPack(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                      const fs::path& pack) {
  UseTensorThreads();
  // The device is the training machine's, not this one's.
  TrainOptions here = options;
  here.device = "cpu";
  HF_RETURN_IF_ERROR(here.Check());
  if (!options.gan_avatar.generator_from.empty())
    return Status::InvalidArgument("pack: --generator-from is for headforge train, which adds the expression mapping "
                                   "to a GAN trained from a pack");
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrainingData(options, workspace, model, &data));
  return WriteDatasetPack(data, ToJson(options), pack);
}

}  // namespace headforge
