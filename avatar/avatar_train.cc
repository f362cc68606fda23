#include "avatar/avatar_train.h"

#include <torch/torch.h>

#include "avatar/gan_avatar/render_expressions.h"
#include "avatar/gan_avatar/trainer.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"
#include "avatar/train/dataset_pack.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/loop.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/paths.h"

namespace headforge {
namespace {

// What a preset sets; every value is also an option of its own.
struct Preset {
  const char* name;
  const char* device;
  int resolution, steps;
  double max_minutes;
  int init_gaussians;
  int64_t max_gaussians;
  int densify_until, triplane_resolution;
  double lr_network;
  int eval_every, preview_every;
  int decoder_steps, prior_steps, pti_steps;  // stage 3
  double validation;
  int patience;
};

// draft: measured on two CPU cores to end within its 15 minutes
// (docs/benchmarks.md); standard: one GPU at 512 px, at most 100 000
// Gaussians (measured on an H200: 25.95 dB held-out and 7.6 ms a frame,
// against 25.08 dB and 14.7 ms with 300 000); high: the paper's learning rate
// and a long run.
const Preset kPresets[] = {
    {"draft", "cpu", 256, 6000, 15, 20000, 40000, 3000, 64, 5e-4, 1000, 1000, 0, 0, 0, 0, 0},
    {"standard", "cuda", 512, 30000, 10, 50000, 100000, 20000, 128, 2e-4, 2000, 2000, 20000, 20000, 500, 0, 0},
    {"high", "cuda", 512, 100000, 0, 100000, 500000, 60000, 256, 1e-4, 5000, 5000, 50000, 50000, 1000, 0, 0},
};

// The gan-avatar model's presets. draft: a 32 px volume render
// super-resolved to 64 px on two CPU cores, every step the reconstruction
// warm-up (measured: within 15 minutes the adversarial steps cost 4 dB on
// the held-out frames, docs/benchmarks.md); standard and high: EG3D's render
// sizes on one GPU, a warm-up and then the GAN (docs/gan_avatar.md). The step sizes are EG3D's
// 0.0025 over ten: the layers here have no equalised learning rate, so their
// weights are about ten times smaller and the same step moves them ten
// times as far (measured: at 2e-3 the discriminator wins within 50 steps).
struct GanPreset {
  const char* name;
  const char* device;
  int resolution, render_resolution, steps;
  double max_minutes;
  int triplane_resolution, batch, reconstruction_steps;
  double lr_network, lr_discriminator, r1_gamma;
  int eval_every, preview_every;
};

const GanPreset kGanPresets[] = {
    {"draft", "cpu", 64, 32, 1800, 15, 64, 4, 1800, 2.5e-4, 2.5e-4, 1.0, 300, 300},
    {"standard", "cuda", 256, 64, 40000, 60, 128, 8, 10000, 2.5e-4, 2.5e-4, 1.0, 2000, 2000},
    {"high", "cuda", 512, 128, 200000, 0, 256, 16, 20000, 2.5e-4, 2.5e-4, 1.0, 5000, 5000},
};

}  // namespace

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
         "Avatar model." + models + " The train stage's auto chooses " + kGanAvatar.Name() +
             " for several cameras or views spread 120 degrees or more round the head (a 360-degree or multi-view "
             "capture), else " + kGaussianStyle.Name() + ".",
         "model");
  o->Add("train.preset", &t->preset,
         "draft (2 CPU cores, 256 px, within 15 min), standard (one GPU, 512 px), high (the paper's scale); it sets "
         "the defaults of the options below that are not given.",
         "preset");
  o->Add("train.device", &t->device, "cpu, or cuda (cuda:N) in a build against a LibTorch with CUDA.", "device",
         OptionSet::Effect::kRuntime);
  o->Add("train.resolution", &t->resolution, "The frames' longer side while training, pixels.", "train-size");
  o->AddOldFlag("train.resolution", "resolution");
  o->Add("train.steps", &t->steps, "Optimisation steps (one view each), both stages.", "steps");
  o->Add("train.max_minutes", &t->max_minutes, "Stop training after this many minutes (0: no limit).", "max-minutes");
  o->Add("train.canonical_fraction", &t->canonical_fraction,
         "The share of the steps in stage 1 (canonical Gaussians and triplanes) before stage 2 (deformation).",
         "canonical-fraction");
  o->Add("train.deform", &t->deform, "Train stage 2, the attention deformation (false: stage 1 only).", "deform");
  o->Add("train.mesh_riding", &t->mesh_riding,
         "Bind the Gaussians to the tracked mesh's triangles, which the tracked expressions move; the network "
         "predicts changes in their frames. --mesh-riding=false: the paper's deformation in canonical space.",
         "mesh-riding");
  o->Add("train.latent_dropout", &t->latent_dropout,
         "Stage 2: the share of training views drawn with frame 0's latent, the one held-out frames and render use, "
         "instead of their own (0: each its own, as the paper).",
         "latent-dropout");
  o->Add("train.region_weight", &t->region_weight, "Weight of stage 2's L1 on the eyes' and mouth's crops (0: none).",
         "region-weight");
  o->Add("train.ssim_weight", &t->ssim_weight, "Loss = (1 - w) L1 + w (1 - SSIM).", "ssim-weight");
  o->Add("train.holdout", &t->holdout, "The fraction of the frames held out for evaluation.", "holdout");
  o->Add("train.validation", &t->validation,
         "gaussian-style: the fraction of the training frames set aside to choose when training stops (never "
         "trained on; the last ones, or interleaved like the hold-out); scored at each --eval-every. 0, or "
         "--eval-every 0: none.",
         "validation");
  o->Add("train.patience", &t->patience,
         "gaussian-style: stop stage 2 once the validation frames' score has not risen for this many evaluations "
         "(0: train every step). Without validation frames it has nothing to wait on and training runs its steps.",
         "patience");
  o->Add("train.holdout_order", &t->holdout_order,
         "Which frames: last (the last ones), interleaved (every round(1/holdout)-th: views between training views) "
         "or auto (interleaved for one camera whose views circle the head 120 degrees or more, else last).",
         "holdout-order");
  o->Add("train.holdout_cameras", &t->holdout_cameras,
         "Cameras held out whole (every frame of theirs scored, none trained on), comma-separated.",
         "holdout-cameras");
  o->Add("train.mask", &t->mask,
         "The head masks trained and scored on: ingest (the workspace's masks), mesh (the workspace's masks cut to "
         "the tracked mesh's silhouette, grown by --mask-hair over the scalp and --mask-skin elsewhere: background "
         "of the skin's colour beside the head is left out) or auto (mesh for gaussian-style, ingest for "
         "gan-avatar).",
         "mask");
  o->Add("train.mask_hair", &t->mask_hair,
         "--mask mesh: how far (metres) the mask may reach beyond the tracked scalp, for hair; raise it for big hair.",
         "mask-hair");
  o->Add("train.mask_skin", &t->mask_skin,
         "--mask mesh: how far (metres) the mask may reach beyond the rest of the tracked mesh (face, ears, neck), "
         "for the tracking's error.",
         "mask-skin");
  o->Add("train.pose_lr", &t->pose_lr,
         "gaussian-style: Adam's step of a rigid correction of each training view's tracked head pose (radians, "
         "metres), learnt with the avatar where the tracked poses are a little off; 0 keeps them. Held-out views "
         "keep their tracked poses.",
         "pose-lr");
  o->Add("train.init_gaussians", &t->init_gaussians, "Gaussians sampled on the tracked mesh to start with.",
         "init-gaussians");
  o->Add("train.max_gaussians", &t->max_gaussians, "Densification adds no more beyond this count.", "max-gaussians");
  o->Add("train.densify_from", &t->densify_from, "First step that densifies.", "densify-from");
  o->Add("train.densify_until", &t->densify_until, "Last step that densifies.", "densify-until");
  o->Add("train.densify_every", &t->densify_every, "Steps between densifications.", "densify-every");
  o->Add("train.grad_threshold", &t->grad_threshold,
         "Mean screen-space gradient above which a Gaussian is cloned or split.", "grad-threshold");
  o->Add("train.lr_network", &t->lr_network, "Adam step of the networks and frame latents.", "lr-network");
  o->Add("train.lr_means", &t->lr_means, "Adam step of the positions (times the extent), decaying to 1%.", "lr-means");
  o->Add("train.lr_quats", &t->lr_quats, "Adam step of the rotations.", "lr-quats");
  o->Add("train.lr_scales", &t->lr_scales, "Adam step of the log-scales.", "lr-scales");
  o->Add("train.lr_opacity", &t->lr_opacity, "Adam step of the opacity logits.", "lr-opacity");
  o->Add("train.lr_features", &t->lr_features, "Adam step of the Gaussians' features.", "lr-features");
  o->Add("train.feature_channels", &t->feature_channels, "Feature channels per Gaussian (the first three RGB).",
         "feature-channels");
  o->Add("train.triplane_resolution", &t->triplane_resolution, "Side of each triplane, a power of two.",
         "triplane-resolution");
  o->Add("train.latent_dim", &t->latent_dim, "Size of each frame's latent.", "latent-dim");
  o->Add("train.render_resolution", &t->render_resolution,
         "gan-avatar: the volume render's longer side; --train-size / this must be a power of two.",
         "render-resolution");
  o->Add("train.batch", &t->batch, "gan-avatar, and stage 3's prior: real and generated views per step.", "batch");
  o->Add("train.reconstruction_steps", &t->reconstruction_steps,
         "gan-avatar: the first steps reconstruct the training frames (L1, a latent per frame) before the "
         "adversarial training: a personal prior in place of pretrained EG3D weights (0: none).",
         "reconstruction-steps");
  o->Add("train.recon_weight", &t->recon_weight,
         "gan-avatar: weight of the reconstruction loss kept beside the adversarial one after the warm-up (0: "
         "adversarial alone).",
         "recon-weight");
  o->Add("train.adversarial_ramp", &t->adversarial_ramp,
         "gan-avatar: steps after the warm-up over which the generator's adversarial loss rises from 0 to 1.",
         "adversarial-ramp");
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
  o->Add("train.coarse_samples", &t->coarse_samples, "gan-avatar: stratified samples per ray.", "samples");
  o->Add("train.fine_samples", &t->fine_samples, "gan-avatar: importance samples per ray (0: none).",
         "fine-samples");
  o->Add("train.mapping_samples", &t->mapping_samples,
         "gan-avatar: latents rendered frontally and tracked to train the expression mapping.", "mapping-samples");
  o->Add("train.mapping_steps", &t->mapping_steps, "gan-avatar: steps of the expression mapping (0: none).",
         "mapping-steps");
  o->Add("train.mapping_loss", &t->mapping_loss,
         "gan-avatar: image (the render of the mapped w against the sampled render, generator frozen) or latent "
         "(the mapped w against the sampled w).",
         "mapping-loss");
  o->Add("train.mapping_latents", &t->mapping_latents,
         "gan-avatar: the latents the mapping's renders come from: random (z ~ N(0, I), the paper's) or frames (the "
         "reconstruction warm-up's latent of each training frame, then blends of two frames').",
         "mapping-latents");
  o->Add("train.landmark_model", &t->landmark_model,
         "gan-avatar: dlib's 68-point landmark model, which reads the renders' landmarks (default: Debian's "
         "libdlib-data).",
         "landmark-model", OptionSet::Effect::kRuntime);
  o->Add("train.generator_from", &t->generator_from,
         "gan-avatar: the folder of a GAN trained already (headforge-train's --out for this workspace's pack, e.g. on "
         "a GPU machine): its generator is taken, only the expression mapping trains here, and the options that "
         "shape the model and its views are the ones recorded there.",
         "generator-from");
  o->Add("train.decoder_steps", &t->decoder_steps,
         "gaussian-style: steps of stage 3, the StyleGAN decoder that turns the splatted 32-channel features into "
         "the image (0: none; the image is the splatted RGB).",
         "decoder-steps");
  o->Add("train.decoder_max_minutes", &t->decoder_max_minutes,
         "gaussian-style: stop stage 3 after this many minutes (0: no limit). Its own limit: --max-minutes stops "
         "stages 1-2, and stage 3's phases are long (its prior first).",
         "decoder-max-minutes");
  o->Add("train.prior_steps", &t->prior_steps,
         "gaussian-style stage 3: steps training the decoder's generator on the training frames (a personal prior in "
         "place of pretrained FFHQ weights) before PTI.",
         "prior-steps");
  o->Add("train.pti_steps", &t->pti_steps,
         "gaussian-style stage 3: PTI's steps inverting the extreme-pose frames, and as many fine-tuning the generator.",
         "pti-steps");
  o->Add("train.pti_frames", &t->pti_frames, "gaussian-style stage 3: the frames of the most extreme head poses PTI uses.",
         "pti-frames");
  o->Add("train.decoder_resolution", &t->decoder_resolution,
         "gaussian-style stage 3: the decoder's square side, a power of two (0: --train-size).", "decoder-resolution");
  o->Add("train.projected_blocks", &t->projected_blocks,
         "gaussian-style stage 3: generator blocks (4, 8, 16, ... px) the encoder's features are fused into.",
         "projected-blocks");
  o->Add("train.adversarial_weight", &t->adversarial_weight,
         "gaussian-style stage 3: weight of the UV-conditioned adversarial loss (0: no discriminator).",
         "adversarial-weight");
  o->Add("train.perceptual_weight", &t->perceptual_weight,
         "gaussian-style stage 3: weight of the discriminator feature matching that stands in for LPIPS.",
         "perceptual-weight");
  o->Add("train.decoder_ada", &t->decoder_ada, "gaussian-style stage 3: adaptive augmentation of the discriminator's inputs.",
         "decoder-ada");
  o->Add("train.full_tune", &t->full_tune,
         "gaussian-style stage 3: no PTI, and the generator trained with the rest (the paper's full-tune ablation).",
         "full-tune");
  o->Add("train.decoder_init", &t->decoder_init,
         "gaussian-style stage 3: a .safetensors file of generator weights to start from instead of the personal "
         "prior (layout in docs/avatar.md).",
         "decoder-init");
  o->Add("train.log_every", &t->log_every, "Steps between lines of stats.jsonl.", "log-every");
  o->Add("train.eval_every", &t->eval_every, "Steps between held-out evaluations (0: only at the end).", "eval-every");
  o->Add("train.preview_every", &t->preview_every, "Steps between preview images (0: none).", "preview-every");
  o->Add("train.checkpoint_every", &t->checkpoint_every,
         "Steps between checkpoints; an interrupted run (Ctrl-C, a kill) resumes from the last.", "checkpoint-every",
         OptionSet::Effect::kRuntime);
  o->Add("train.seed", &t->seed, "Seed of the initial Gaussians, the networks, the view order and backgrounds.",
         "train-seed");
}

Status ApplyTrainPreset(const OptionSet& parsed, TrainOptions* t) {
  auto fill = [&](const char* key, auto* field, auto value) {
    if (!parsed.WasGiven(key)) *field = value;
  };
  if (kGanAvatar.Is(t->model)) {
    const GanPreset* preset = nullptr;
    for (const GanPreset& p : kGanPresets)
      if (t->preset == p.name) preset = &p;
    if (!preset)
      return Status::InvalidArgument("train: --preset must be draft, standard or high, not '" + t->preset + "'");
    fill("train.device", &t->device, std::string(preset->device));
    fill("train.resolution", &t->resolution, preset->resolution);
    fill("train.render_resolution", &t->render_resolution, preset->render_resolution);
    fill("train.steps", &t->steps, preset->steps);
    fill("train.max_minutes", &t->max_minutes, preset->max_minutes);
    fill("train.triplane_resolution", &t->triplane_resolution, preset->triplane_resolution);
    fill("train.batch", &t->batch, preset->batch);
    fill("train.reconstruction_steps", &t->reconstruction_steps, preset->reconstruction_steps);
    fill("train.lr_network", &t->lr_network, preset->lr_network);
    fill("train.lr_discriminator", &t->lr_discriminator, preset->lr_discriminator);
    fill("train.r1_gamma", &t->r1_gamma, preset->r1_gamma);
    fill("train.eval_every", &t->eval_every, preset->eval_every);
    fill("train.preview_every", &t->preview_every, preset->preview_every);
    return Status::Ok();
  }
  const Preset* preset = nullptr;
  for (const Preset& p : kPresets)
    if (t->preset == p.name) preset = &p;
  if (!preset) return Status::InvalidArgument("train: --preset must be draft, standard or high, not '" + t->preset + "'");
  fill("train.device", &t->device, std::string(preset->device));
  fill("train.resolution", &t->resolution, preset->resolution);
  fill("train.steps", &t->steps, preset->steps);
  fill("train.max_minutes", &t->max_minutes, preset->max_minutes);
  fill("train.init_gaussians", &t->init_gaussians, preset->init_gaussians);
  fill("train.max_gaussians", &t->max_gaussians, preset->max_gaussians);
  fill("train.densify_until", &t->densify_until, preset->densify_until);
  fill("train.triplane_resolution", &t->triplane_resolution, preset->triplane_resolution);
  fill("train.lr_network", &t->lr_network, preset->lr_network);
  fill("train.eval_every", &t->eval_every, preset->eval_every);
  fill("train.preview_every", &t->preview_every, preset->preview_every);
  // Stage 3's GANs (the prior, the UV-conditioned discriminator) step as the gan-avatar's do.
  fill("train.lr_discriminator", &t->lr_discriminator, 2.5e-4);
  fill("train.r1_gamma", &t->r1_gamma, 1.0);
  fill("train.decoder_steps", &t->decoder_steps, preset->decoder_steps);
  fill("train.prior_steps", &t->prior_steps, preset->prior_steps);
  fill("train.pti_steps", &t->pti_steps, preset->pti_steps);
  fill("train.validation", &t->validation, preset->validation);
  fill("train.patience", &t->patience, preset->patience);
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
  const double spread = cameras.AzimuthSpreadDeg();
  char text[160];
  if (cameras.cameras.size() > 1) {
    std::snprintf(text, sizeof(text), "%zu cameras: a multi-view capture", cameras.cameras.size());
    *model = kGanAvatar.Name();
  } else if (cameras.WalksRoundTheHead()) {
    std::snprintf(text, sizeof(text), "one camera whose views spread %.0f deg round the head", spread);
    *model = kGanAvatar.Name();
  } else {
    std::snprintf(text, sizeof(text), "one camera, its views within %.0f deg of one another (%s cameras)", spread,
                  cameras.mode.c_str());
    *model = kGaussianStyle.Name();
  }
  *why = text;
  return Status::Ok();
}

namespace {

// The workspace's views as the run of `options` trains on them (with the UV
// maps stage 3's discriminator needs).
Status LoadTrainingData(const TrainOptions& options, const fs::path& workspace, const FaceModel& model,
                        AvatarDataset* data) {
  DatasetOptions loading;
  loading.resolution = options.resolution;
  loading.holdout = options.holdout;
  loading.holdout_order = options.holdout_order;
  loading.holdout_cameras = options.holdout_cameras;
  loading.mask = options.MaskFor(*FindAvatarModel(options.model));
  loading.mask_hair = options.mask_hair;
  loading.mask_skin = options.mask_skin;
  if (kGaussianStyle.Is(options.model) && options.decoder_steps > 0 && options.adversarial_weight > 0)
    loading.uv_map_side = options.decoder_resolution > 0 ? options.decoder_resolution : options.resolution;
  HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, model, loading, data).WithContext("train"));
  HF_LOG(Info) << "train: " << data->train.size() << " training and " << data->test.size() << " held-out views at "
               << data->width << "x" << data->height << " (held out: " << data->HeldOutText() << ")";
  return Status::Ok();
}

}  // namespace

namespace {

// --generator-from DIR: the options DIR's training recorded, with this
// command's for what only the mapping and this machine use.
Status AdoptRecordedOptions(const TrainOptions& options, TrainOptions* resolved) {
  const fs::path dir = options.generator_from;
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
  resolved->mapping_samples = options.mapping_samples;
  resolved->mapping_steps = options.mapping_steps;
  resolved->mapping_loss = options.mapping_loss;
  resolved->mapping_latents = options.mapping_latents;
  resolved->landmark_model = options.landmark_model;
  resolved->log_every = options.log_every;
  resolved->checkpoint_every = options.checkpoint_every;
  resolved->generator_from = options.generator_from;
  HF_LOG(Info) << "train: the GAN of " << dir.string() << " (resolution " << resolved->resolution << ", render "
               << resolved->render_resolution << ", preset " << resolved->preset
               << "): its recorded options shape the model and the views";
  return resolved->Check();
}

}  // namespace

Status RunTrain(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                const fs::path& out_dir, Progress* progress, TrainSummary* summary) {
  UseTensorThreads();
  HF_RETURN_IF_ERROR(options.Check());
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  TrainOptions resolved = options;
  if (!options.generator_from.empty()) HF_RETURN_IF_ERROR(AdoptRecordedOptions(options, &resolved));
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrainingData(resolved, workspace, model, &data));
  if (!kGanAvatar.Is(resolved.model)) return TrainGaussianStyleRun(resolved, data, out_dir, progress, summary);
  if (resolved.landmark_model.empty()) resolved.landmark_model = DefaultLandmarkModel();
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(workspace / "tracking.json", &tracking));
  const ImageTracker track_images = [&](const torch::Tensor& images, const std::vector<SplatCamera>& cameras,
                                        Progress* p, RenderExpressions* out) {
    RenderExpressionOptions reading;
    reading.landmark_model = resolved.landmark_model;
    reading.threads = TensorThreads();
    return EstimateImageExpressions(images, cameras, model, tracking, reading, p, out);
  };
  return TrainGanAvatar(resolved, data, track_images, out_dir, progress, summary);
}

Status WriteTrainPack(const TrainOptions& options, const fs::path& workspace, const std::string& face_model,
                      const fs::path& pack) {
  UseTensorThreads();
  // The device is the training machine's, not this one's.
  TrainOptions here = options;
  here.device = "cpu";
  HF_RETURN_IF_ERROR(here.Check());
  if (!options.generator_from.empty())
    return Status::InvalidArgument("pack: --generator-from is for headforge train, which adds the expression mapping "
                                   "to a GAN trained from a pack");
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrainingData(options, workspace, model, &data));
  return WriteDatasetPack(data, ToJson(options), pack);
}

}  // namespace headforge
