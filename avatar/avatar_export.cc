#include "avatar/avatar_export.h"

#include <map>

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "avatar/gan_avatar/avatar_io.h"
#include "avatar/gaussian_style/trainer.h"
#include "core/json_io.h"
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

}  // namespace headforge
