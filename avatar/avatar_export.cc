#include "avatar/avatar_export.h"

#include <chrono>
#include <cstring>
#include <functional>
#include <map>

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "avatar/gan_avatar/avatar_io.h"
#include "avatar/gaussian_style/blendshapes.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/train/view_scores.h"
#include "core/json_io.h"
#include "core/log.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

std::vector<float> Floats(const torch::Tensor& t) {
  const torch::Tensor c = t.detach().to(torch::kFloat32).cpu().contiguous();
  return std::vector<float>(c.data_ptr<float>(), c.data_ptr<float>() + c.numel());
}

}  // namespace

Status PoseAvatarFrames(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                        const std::vector<int>& frames,
                        const std::function<Status(int frame, const AvatarSplats& splats)>& each) {
  GaussianStyleAvatar avatar;
  FaceModel model;
  DatasetOptions loading;
  loading.images = false;
  AvatarDataset data;
  HF_RETURN_IF_ERROR(
      LoadTrained(workspace, model_dir, face_model, torch::kCPU, 0, &loading, &avatar, &model, &data));
  std::map<int, const AvatarView*> views;
  for (const auto* list : {&data.train, &data.test})
    for (const AvatarView& v : *list) views.emplace(v.frame, &v);
  for (int frame : frames) {
    const int wanted = frame == kNeutralFrame ? 0 : frame;
    const auto view = views.find(wanted);
    if (view == views.end())
      return Status::InvalidArgument("export: no frame " + std::to_string(wanted) + " (the frames run 0-" +
                                     std::to_string(data.num_frames - 1) + ")");
    torch::Tensor condition = view->second->condition.clone();
    if (frame == kNeutralFrame) condition.slice(0, 0, int64_t(data.expression_names.size())).zero_();
    torch::NoGradGuard no_grad;
    const PosedGaussians posed = avatar.Pose(data, condition, 0, avatar.deform);
    AvatarSplats out;
    out.means = Floats(posed.means);
    out.rotations =
        Floats(torch::nn::functional::normalize(posed.quats, torch::nn::functional::NormalizeFuncOptions().dim(1)));
    out.scales = Floats(posed.log_scales.exp());
    out.opacities = Floats(posed.opacities);
    out.colours = Floats(posed.features.slice(1, 0, 3).clamp(0, 1));
    HF_RETURN_IF_ERROR(each(frame, out));
  }
  return Status::Ok();
}

Status PoseAvatarSplats(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                        int frame, AvatarSplats* splats) {
  return PoseAvatarFrames(workspace, model_dir, face_model, {frame}, [&](int, const AvatarSplats& posed) {
    *splats = posed;
    return Status::Ok();
  });
}

Status ExportAvatarWeights(const fs::path& workspace, const fs::path& model_dir, const fs::path& out_dir,
                           std::vector<std::string>* files) {
  GaussianStyleAvatar avatar;
  HF_RETURN_IF_ERROR(LoadAvatar(model_dir, torch::kCPU, &avatar, nullptr));
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadArtefact(model_dir / "config.json", 1, "train", &config));
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(workspace / "tracking.json", &tracking));
  config["face_model"] = fs::path(tracking.face_model).filename().string();
  config["identity"] = std::vector<double>(tracking.identity.data(), tracking.identity.data() + tracking.identity.size());
  config["identity_note"] =
      "the face model's identity coefficients in standard deviations; the mesh is the model's mean shape plus its "
      "identity basis times these";
  config["condition"] =
      "one vector per frame: the expression weights in expression_names' order, in [0, 1], then the head pose as "
      "the first two columns of its rotation (6 numbers, column by column) and its translation in metres";
  config["tensors"] = {
      {"gaussians.means", "[N, 3] canonical positions, metres (with mesh riding: in the bound triangle's frame)"},
      {"gaussians.quats", "[N, 4] rotations w, x, y, z, not normalised"},
      {"gaussians.log_scales", "[N, 3] natural logarithms of the standard deviations"},
      {"gaussians.opacity_logits", "[N] opacity before the sigmoid"},
      {"gaussians.features", "[N, F] features; the first three are RGB before the sigmoid"},
      {"gaussians.binding", "[N] int64 triangle of the face model each Gaussian rides (mesh riding only)"},
      {"model.*", "the networks' parameters, named by their module path"}};
  if (avatar.decoder) config["tensors"]["decoder.*"] = "stage 3's decoder (encoder, projections, generator), by module path";
  if (avatar.pose_corrections.defined())
    config["tensors"]["pose_corrections"] =
        "[training views, 6] each training view's head-pose correction (--pose-lr): rotation vector, translation in "
        "metres";
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  HF_RETURN_IF_ERROR(SaveAvatarSafetensors(avatar, config, out_dir));
  if (files) {
    files->push_back("weights.safetensors");
    files->push_back("config.json");
  }
  return Status::Ok();
}

Status ExportGanWeights(const fs::path& workspace, const fs::path& model_dir, const fs::path& out_dir,
                        std::vector<std::string>* files) {
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(workspace / "tracking.json", &tracking));
  const nlohmann::json extra = {
      {"face_model", fs::path(tracking.face_model).filename().string()},
      {"identity", std::vector<double>(tracking.identity.data(), tracking.identity.data() + tracking.identity.size())},
      {"condition",
       "the expression mapping takes the expression weights in expression_mapping's order, in [0, 1]; the head "
       "pose is the camera's, in the head frame of the face model"}};
  HF_RETURN_IF_ERROR(ExportGanAvatarWeights(model_dir, extra, out_dir));
  if (files) {
    files->push_back("weights.safetensors");
    files->push_back("config.json");
  }
  return Status::Ok();
}

// ExportAvatarBlendshapes: the distillation, its scores on the held-out
// frames and its files.
namespace {


double SecondsFrom(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The held-out views drawn by `pose` (a view -> its Gaussians) as RGB splats
// over the grey training's scores use.
std::vector<ViewScores> ScoreHeldOut(const AvatarDataset& data,
                                     const std::function<PosedGaussians(const AvatarView&)>& pose) {
  torch::NoGradGuard no_grad;
  const torch::Tensor background = torch::full({3}, kEvalBackground);
  std::vector<ViewScores> scores;
  for (const AvatarView& view : data.test) {
    const auto start = std::chrono::steady_clock::now();
    const torch::Tensor render = RenderRgb(pose(view), view.view, background).clamp(0, 1);
    const double ms = 1000 * SecondsFrom(start);
    ViewScores s = ScoreRender(render, view.image, view.mask, background);
    s.render_ms = ms;
    scores.push_back(s);
  }
  return scores;
}

Status WriteBlendshapeFiles(const GaussianBlendshapes& shapes, const BlendshapeScores& scores,
                            const DatasetOptions& data, const fs::path& dir, std::vector<std::string>* files) {
  const int64_t n = shapes.neutral.size(0), k = shapes.offsets.size(0);
  std::string bytes;
  for (const torch::Tensor& t : {shapes.opacities, shapes.neutral, shapes.offsets}) {
    const torch::Tensor c = t.to(torch::kFloat32).cpu().contiguous();
    bytes.append(reinterpret_cast<const char*>(c.data_ptr<float>()), size_t(c.numel()) * sizeof(float));
  }
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  HF_RETURN_IF_ERROR(WriteFileAtomic(dir / "blendshapes.bin", bytes));
  const torch::Tensor pose = shapes.pose_condition.to(torch::kFloat64).contiguous();
  const nlohmann::json layout = {
      {"format", "headforge-gaussian-blendshapes"},
      {"version", 1},
      {"gaussians", n},
      {"expressions", shapes.names},
      {"attributes", {"position_x", "position_y", "position_z", "rotation_w", "rotation_x", "rotation_y",
                      "rotation_z", "log_scale_x", "log_scale_y", "log_scale_z", "red", "green", "blue"}},
      {"binary", {{"file", "blendshapes.bin"},
                  {"type", "float32 little-endian"},
                  {"opacities", {{"offset", 0}, {"shape", {n}}}},
                  {"neutral", {{"offset", 4 * n}, {"shape", {n, kBlendshapeAttributes}}}},
                  {"offsets",
                   {{"offset", 4 * n * (1 + kBlendshapeAttributes)}, {"shape", {k, n, kBlendshapeAttributes}}}}}},
      {"pose", "attributes = neutral + sum_k weight_k * offsets[k], in the head frame (metres, +y up, the face "
               "toward +z); normalise the rotation, scale = exp(log_scale), clamp the colour to [0, 1]; the head's "
               "rigid motion goes on top"},
      {"pose_condition", std::vector<double>(pose.data_ptr<double>(), pose.data_ptr<double>() + pose.numel())},
      {"held_out",
       {{"views", scores.held_out_views},
        {"psnr_masked_network", scores.psnr_network},
        {"psnr_masked_blendshapes", scores.psnr_blendshapes},
        {"psnr_masked_fitted", scores.psnr_fitted},
        {"psnr_masked_pruned", scores.psnr_pruned},
        {"ms_network", scores.ms_network},
        {"ms_blendshapes", scores.ms_blendshapes}}},
      {"data", ToJson(data)},
      {"samples", scores.samples},
      {"fit_seconds", scores.fit_seconds},
      {"pruning",
       {{"gaussians_fitted", scores.gaussians_fitted},
        {"gaussians_kept", scores.gaussians},
        {"light_kept", scores.prune_light_kept},
        {"seconds", scores.prune_seconds},
        {"kept", scores.pruned_kept}}},
      {"refinement",
       {{"steps", scores.refine_steps},
        {"kept_step", scores.refine_kept_step},
        {"validation_views", scores.validation_views},
        {"validation_psnr_masked_before", scores.validation_psnr_before},
        {"validation_psnr_masked_after", scores.validation_psnr_after},
        {"seconds", scores.refine_seconds},
        {"validation_curve", scores.validation_curve}}}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(dir / "blendshapes.json", layout, 1));
  files->insert(files->end(), {"blendshapes.bin", "blendshapes.json"});
  return Status::Ok();
}

AvatarBlendshapes Arrays(const GaussianBlendshapes& shapes) {
  AvatarBlendshapes out;
  const torch::Tensor a = shapes.neutral;
  out.neutral.means = Floats(a.slice(1, 0, 3));
  out.neutral.rotations = Floats(a.slice(1, 3, 7) / a.slice(1, 3, 7).norm(2, 1, true).clamp_min(1e-12));
  out.neutral.scales = Floats(a.slice(1, 7, 10).exp());
  out.neutral.opacities = Floats(shapes.opacities);
  out.neutral.colours = Floats(a.slice(1, 10, 13).clamp(0, 1));
  out.names = shapes.names;
  out.offsets = Floats(shapes.offsets);
  out.neutral_attributes = Floats(a);
  return out;
}

}  // namespace

Status ExportAvatarBlendshapes(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                               const BlendshapeExportOptions& export_options, const fs::path& out_dir,
                               BlendshapeScores* scores, std::vector<std::string>* files, AvatarBlendshapes* arrays,
                               Progress* progress) {
  GaussianStyleAvatar avatar;
  FaceModel model;
  DatasetOptions loading;
  AvatarDataset data;
  HF_RETURN_IF_ERROR(LoadTrained(workspace, model_dir, face_model, torch::kCPU, 0, &loading, &avatar, &model, &data)
                         .WithContext("export blendshapes"));
  if (!avatar.deform)
    HF_LOG(Warning) << "export: the avatar trained without stage 2, so its blendshapes do not move it";
  const auto start = std::chrono::steady_clock::now();
  const DistilOptions options;
  GaussianBlendshapes shapes = DistilBlendshapes(avatar, data, options);
  scores->fit_seconds = SecondsFrom(start);
  const int64_t k = int64_t(data.expression_names.size());
  scores->gaussians = int(shapes.neutral.size(0));
  scores->expressions = int(k);
  scores->samples = int(data.train.size()) * (1 + options.perturbed_per_view) + 1;
  const std::vector<ViewScores> network = ScoreHeldOut(data, [&](const AvatarView& view) {
    return avatar.Pose(data, view, 0, avatar.deform);
  });
  auto linear = [&] {
    return ScoreHeldOut(data, [&](const AvatarView& view) { return PoseBlendshapes(shapes, view.condition.slice(0, 0, k)); });
  };
  const std::vector<ViewScores> fitted = linear();
  scores->held_out_views = int(data.test.size());
  scores->psnr_network = MeanScores(network).psnr_masked;
  scores->psnr_fitted = MeanScores(fitted).psnr_masked;
  scores->ms_network = MeanRenderMs(network);
  HF_LOG(Info) << "export: " << scores->gaussians << " Gaussians x " << k << " blendshapes fitted to "
               << scores->samples << " poses of the networks in " << scores->fit_seconds << " s; held out "
               << scores->psnr_fitted << " dB over the head against the networks' " << scores->psnr_network << " dB";
  std::vector<ViewScores> final_scores = fitted;
  scores->gaussians_fitted = scores->gaussians;
  scores->psnr_pruned = scores->psnr_fitted;
  if (export_options.prune > 0) {
    BlendshapePruneReport pruned;
    HF_RETURN_IF_ERROR(PruneBlendshapes(data, export_options.prune, &shapes, &pruned).WithContext("export blendshapes"));
    scores->gaussians = pruned.after;
    scores->prune_light_kept = pruned.light_kept;
    scores->prune_seconds = pruned.seconds;
    scores->pruned_kept = pruned.kept;
    final_scores = linear();
    scores->psnr_pruned = MeanScores(final_scores).psnr_masked;
    HF_LOG(Info) << "export: " << pruned.after << " Gaussians left score " << scores->psnr_pruned
                 << " dB held out over the head before the refinement";
  }
  if (export_options.refine_steps > 0) {
    BlendshapeRefineOptions refine;
    refine.steps = export_options.refine_steps;
    refine.max_minutes = export_options.refine_minutes;
    BlendshapeRefineReport report;
    HF_RETURN_IF_ERROR(RefineBlendshapes(data, refine, &shapes, &report, progress).WithContext("export blendshapes"));
    scores->refine_steps = report.steps;
    scores->refine_kept_step = report.kept_step;
    scores->validation_views = report.validation_views;
    scores->validation_psnr_before = report.validation_psnr_before;
    scores->validation_psnr_after = report.validation_psnr_after;
    scores->refine_seconds = report.seconds;
    scores->validation_curve = report.curve;
    final_scores = linear();
  }
  scores->psnr_blendshapes = MeanScores(final_scores).psnr_masked;
  scores->ms_blendshapes = MeanRenderMs(final_scores);
  HF_LOG(Info) << "export: the blendshapes score " << scores->psnr_blendshapes << " dB held out over the head ("
               << scores->ms_blendshapes << " ms a view against the networks' " << scores->ms_network << ")";
  HF_RETURN_IF_ERROR(WriteBlendshapeFiles(shapes, *scores, loading, out_dir, files));
  if (arrays) *arrays = Arrays(shapes);
  return Status::Ok();
}

}  // namespace headforge
