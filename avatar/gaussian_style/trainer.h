// Training the gaussian-style avatar (stages 1 and 2) on an AvatarDataset,
// rendering it, and scoring its renders; the pieces RunTrain
// (avatar/avatar_train.h), `headforge render` and the benches share.
#pragma once

#include <torch/types.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "avatar/avatar_train.h"
#include "avatar/gaussian_style/decoder.h"
#include "avatar/gaussian_style/model.h"
#include "avatar/train/dataset.h"
#include "avatar/train/view_scores.h"
#include "core/face_model.h"
#include "core/stats_log.h"

namespace headforge {

// Everything that renders a trained avatar.
struct GaussianStyleAvatar {
  GaussianStyle model{nullptr};
  AvatarGaussians gaussians;
  TriangleFrames neutral;  // the mesh without expression (mesh riding)
  bool deform = true;      // trained with stage 2
  StyleDecoder decoder{nullptr};  // trained with stage 3: the image is the decoder's
  // [training views, 6]: each training view's head-pose correction
  // (--pose-lr), applied wherever a training view is drawn as it was
  // trained (stage 3, the training views' scores); undefined without.
  torch::Tensor pose_corrections;

  // The Gaussians for `condition` [E + 9] with frame latent `latent`; with
  // mesh riding they ride the mesh of the condition's expressions:
  // `vertices` [V, 3] when the caller has it (AvatarDataset::Vertices),
  // else computed here.
  PosedGaussians Pose(const AvatarDataset& data, const torch::Tensor& condition, int64_t latent,
                      bool deform_now, const torch::Tensor& vertices = torch::Tensor());
  // The same for one of the dataset's views: its condition, on its frame's
  // mesh as the dataset holds it.
  PosedGaussians Pose(const AvatarDataset& data, const AvatarView& view, int64_t latent, bool deform_now);
  // The avatar's image [3, H, W] of `posed` through `camera`: the decoder's
  // (over the grey it was trained on) when there is one, else the splatted
  // RGB over `background` [3].
  torch::Tensor Draw(const PosedGaussians& posed, const SplatCamera& camera, const torch::Tensor& background);
};

// The splat image's background in stage 3 and after: grey RGB, zero features.
inline constexpr double kDecoderBackground = 0.5;
// The grey behind the head where held-out and training views are scored.
inline constexpr double kEvalBackground = 0.5;
// `posed`'s C-channel features splatted on the decoder's square canvas and
// decoded, cut back to `camera`'s image (resized when its size differs) -> [3, H, W].
torch::Tensor DecodeRender(StyleDecoderImpl& decoder, const PosedGaussians& posed, const SplatCamera& camera);

// Gaussians sampled by area on the tracked identity's face, scalp, neck,
// ears, eyes, teeth and mouth (not the eyelashes or the eyes' shells), grey
// or the colour the first training views see there.
Status InitGaussians(const AvatarDataset& data, const TrainOptions& options,
                     const GaussianStyleAvatar& avatar, AvatarGaussians* gaussians);

// The RGB render [3, H, W] of `view`'s camera over `background` [3].
torch::Tensor RenderRgb(const PosedGaussians& posed, const SplatCamera& camera, const torch::Tensor& background);

// The model file (model.pt + config.json in `dir`).
Status SaveAvatar(const GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data,
                  const fs::path& dir);
// The config.json train writes for `avatar`, which export adds to: the
// model ("architecture", "decoder", the frames and their size) and the
// options it trained with ("options": ToJson(options), the common part, the
// views with their mask resolved, the loop and this model's block).
nlohmann::json ConfigJson(const GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data);
// The same tensors as weights.safetensors (names as in model.pt) beside `config`.
Status SaveAvatarSafetensors(const GaussianStyleAvatar& avatar, const nlohmann::json& config, const fs::path& dir);
// From model.pt, or from weights.safetensors where there is no model.pt;
// `trained` (when given): the views it trained on, as config.json records
// them (in files written before "options", at its top).
Status LoadAvatar(const fs::path& dir, torch::Device device, GaussianStyleAvatar* avatar, DatasetOptions* trained);

// The avatar in `model_dir` and `workspace`'s views at `resolution` (0: the
// training resolution), held out as in training, ready to pose;
// loading->images says whether the frames are read too.
Status LoadTrained(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                   torch::Device device, int resolution, DatasetOptions* loading, GaussianStyleAvatar* avatar,
                   FaceModel* model, AvatarDataset* data);

// Every `stride`-th held-out (or training) view drawn as the avatar draws
// it (inference: frame 0's latent; training views their own) and scored,
// each render | target | error written into `write_dir` when given.
std::vector<ViewScores> EvaluateAvatar(GaussianStyleAvatar& avatar, const AvatarDataset& data, int stride,
                                       const fs::path& write_dir, bool training_views = false);
// The same for the validation views, drawn as the held-out ones are.
std::vector<ViewScores> EvaluateValidation(GaussianStyleAvatar& avatar, const AvatarDataset& data);
// `fraction` of `data`'s training frames (all their views) moved from
// data->train to data->validation: the last ones, or every
// round(1 / fraction)-th when the hold-out is interleaved. Nothing moves
// when fewer than kFewestTrainingFrames would be left; returns the frames moved.
int SetValidationAside(double fraction, AvatarDataset* data);
// The held-out views' scores as eval.json (with `extra` merged in), the
// model file, and the summary's figures.
// Removes the Gaussians whose centre no training view shows over the person
// (outside every view's mask, or its frame): nothing in training looked at
// them, and a viewer turning the avatar would show them (a cloud below the
// chin). Posed as each view poses them; returns how many went.
int64_t PruneUnseenGaussians(GaussianStyleAvatar& avatar, const AvatarDataset& data);

Status FinishAvatar(GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data,
                    const fs::path& out_dir, const nlohmann::json& extra, TrainSummary* summary);

// Stage 3 (decoder.h) on `avatar` (stages 1-2 done) into `out_dir`:
// decoder_checkpoint.pt between attempts (once it is written,
// `stage2_checkpoint` is removed), `seconds` its training time.
Status TrainStyleDecoder(const TrainOptions& options, const AvatarDataset& data, GaussianStyleAvatar* avatar,
                         const fs::path& out_dir, const fs::path& stage2_checkpoint, StatsLog* stats,
                         Progress* progress, double* seconds);

// Stages 1 and 2, then stage 3 when --decoder-steps asks, into `out_dir`
// (checkpoint.pt and decoder_checkpoint.pt between attempts; a run that finds
// one continues from it).
Status TrainGaussianStyle(const TrainOptions& options, const AvatarDataset& data, const fs::path& out_dir,
                          StatsLog* stats, Progress* progress, TrainSummary* summary);
// The same with out_dir's stats.jsonl opened (OpenTrainStats) and the
// summary's outputs listed: the train stage's run, and a run from a pack.
Status TrainGaussianStyleRun(const TrainOptions& options, const AvatarDataset& data, const fs::path& out_dir,
                             Progress* progress, TrainSummary* summary);

}  // namespace headforge
