// ExportAvatarBlendshapes (avatar_export.h): the distillation, its scores on
// the held-out frames and its two files.
#include <chrono>
#include <cstring>

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "avatar/avatar_export.h"
#include "avatar/gaussian_style/blendshapes.h"
#include "avatar/train/view_scores.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {
namespace {

double SecondsFrom(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The held-out views drawn by `pose` (a view -> its Gaussians) as RGB splats
// over the grey training's scores use.
constexpr double kEvalBackground = 0.5;
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
        {"ms_network", scores.ms_network},
        {"ms_blendshapes", scores.ms_blendshapes}}},
      {"data", ToJson(data)},
      {"samples", scores.samples},
      {"fit_seconds", scores.fit_seconds}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(dir / "blendshapes.json", layout, 1));
  files->insert(files->end(), {"blendshapes.bin", "blendshapes.json"});
  return Status::Ok();
}

std::vector<float> Floats(const torch::Tensor& t) {
  const torch::Tensor c = t.detach().to(torch::kFloat32).cpu().contiguous();
  return std::vector<float>(c.data_ptr<float>(), c.data_ptr<float>() + c.numel());
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
                               const fs::path& out_dir, BlendshapeScores* scores, std::vector<std::string>* files,
                               AvatarBlendshapes* arrays) {
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
  const GaussianBlendshapes shapes = DistilBlendshapes(avatar, data, options);
  scores->fit_seconds = SecondsFrom(start);
  const int64_t k = int64_t(data.expression_names.size());
  scores->gaussians = int(shapes.neutral.size(0));
  scores->expressions = int(k);
  scores->samples = int(data.train.size()) * (1 + options.perturbed_per_view) + 1;
  const std::vector<ViewScores> network = ScoreHeldOut(data, [&](const AvatarView& view) {
    return avatar.Pose(data, view.condition, 0, avatar.deform);
  });
  const std::vector<ViewScores> linear = ScoreHeldOut(data, [&](const AvatarView& view) {
    return PoseBlendshapes(shapes, view.condition.slice(0, 0, k));
  });
  scores->held_out_views = int(data.test.size());
  scores->psnr_network = MeanScores(network).psnr_masked;
  scores->psnr_blendshapes = MeanScores(linear).psnr_masked;
  scores->ms_network = MeanRenderMs(network);
  scores->ms_blendshapes = MeanRenderMs(linear);
  HF_LOG(Info) << "export: " << scores->gaussians << " Gaussians x " << k << " blendshapes fitted to "
               << scores->samples << " poses of the networks in " << scores->fit_seconds << " s; held out "
               << scores->psnr_blendshapes << " dB over the head against the networks' " << scores->psnr_network
               << " dB (" << scores->ms_blendshapes << " ms a view against " << scores->ms_network << ")";
  HF_RETURN_IF_ERROR(WriteBlendshapeFiles(shapes, *scores, loading, out_dir, files));
  if (arrays) *arrays = Arrays(shapes);
  return Status::Ok();
}

}  // namespace headforge
