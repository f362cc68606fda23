#include "avatar/gaussian_style/blendshapes.h"

#include <algorithm>
#include <cstring>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {

torch::Tensor FitLinearModel(const torch::Tensor& inputs, const torch::Tensor& outputs, double ridge) {
  TORCH_CHECK(inputs.dim() == 2 && outputs.dim() == 2 && inputs.size(0) == outputs.size(0),
              "FitLinearModel: inputs [S, K] and outputs [S, M]");
  const torch::Tensor x = inputs.to(torch::kFloat64), y = outputs.to(torch::kFloat64);
  // Centred, the intercept separates from the slopes: slopes from the
  // (damped) normal equations of the centred samples, then the intercept.
  const torch::Tensor x_mean = x.mean(0, true), y_mean = y.mean(0, true);
  const torch::Tensor xc = x - x_mean, yc = y - y_mean;
  torch::Tensor gram = xc.t().matmul(xc);
  gram = gram + ridge * double(x.size(0)) * torch::eye(x.size(1), gram.options());
  const torch::Tensor slopes = torch::linalg::solve(gram, xc.t().matmul(yc), true);
  const torch::Tensor intercept = y_mean - x_mean.matmul(slopes);
  return torch::cat({intercept, slopes}, 0);
}

namespace {

// A posed avatar's attributes [N, 13] (kBlendshapeAttributes); rotations as
// unit quaternions on the side of `reference` [N, 4] where given.
torch::Tensor Attributes(const PosedGaussians& posed, const torch::Tensor& reference) {
  torch::Tensor q = posed.quats / posed.quats.norm(2, 1, true).clamp_min(1e-12);
  if (reference.defined()) q = torch::where((q * reference).sum(1, true) < 0, -q, q);
  return torch::cat({posed.means, q, posed.log_scales, posed.features.slice(1, 0, 3)}, 1);
}

}  // namespace

GaussianBlendshapes DistilBlendshapes(GaussianStyleAvatar& avatar, const AvatarDataset& data,
                                      const DistilOptions& options) {
  torch::NoGradGuard no_grad;
  const int64_t k = int64_t(data.expression_names.size());
  TORCH_CHECK(!data.train.empty(), "DistilBlendshapes: no training views");
  std::vector<torch::Tensor> expressions, poses;
  for (const AvatarView& view : data.train) {
    expressions.push_back(view.condition.slice(0, 0, k).to(torch::kFloat32));
    poses.push_back(view.condition.slice(0, k).to(torch::kFloat32));
  }
  const torch::Tensor tracked = torch::stack(expressions);
  auto generator = at::detail::createCPUGenerator(options.seed);
  std::vector<torch::Tensor> samples = {torch::zeros({1, k}), tracked};
  for (int r = 0; r < options.perturbed_per_view; ++r)
    samples.push_back((tracked + options.spread * torch::randn(tracked.sizes(), generator)).clamp(0, 1));
  const torch::Tensor inputs = torch::cat(samples, 0);  // [S, K], the neutral expression first

  GaussianBlendshapes out;
  out.names = data.expression_names;
  out.pose_condition = torch::stack(poses).mean(0);
  const torch::Device device = avatar.gaussians.params.means.device();
  std::vector<torch::Tensor> rows;
  torch::Tensor reference;
  // The samples' meshes a batch at a time: one product for each.
  constexpr int64_t kMeshBatch = 64;
  torch::Tensor meshes;
  for (int64_t s = 0; s < inputs.size(0); ++s) {
    if (s % kMeshBatch == 0) {
      const torch::Tensor batch = inputs.slice(0, s, std::min(s + kMeshBatch, inputs.size(0)));
      meshes = data.Vertices(batch.unbind(0));
    }
    const torch::Tensor condition = torch::cat({inputs[s], out.pose_condition});
    const PosedGaussians posed = avatar.Pose(data, condition.to(device), 0, avatar.deform, meshes[s % kMeshBatch]);
    if (s == 0) {
      reference = posed.quats / posed.quats.norm(2, 1, true).clamp_min(1e-12);
      out.opacities = posed.opacities.cpu();
    }
    rows.push_back(Attributes(posed, reference).reshape({-1}).cpu());
  }
  const int64_t n = out.opacities.size(0);
  const torch::Tensor model = FitLinearModel(inputs, torch::stack(rows), options.ridge).to(torch::kFloat32);
  out.neutral = model[0].reshape({n, kBlendshapeAttributes});
  out.offsets = model.slice(0, 1).reshape({k, n, kBlendshapeAttributes});
  return out;
}

PosedGaussians PoseBlendshapes(const GaussianBlendshapes& shapes, const torch::Tensor& expression) {
  const int64_t k = shapes.offsets.size(0), n = shapes.neutral.size(0);
  const torch::Tensor weights = expression.to(torch::kFloat32).to(shapes.neutral.device()).reshape({1, k});
  const torch::Tensor a =
      shapes.neutral + weights.matmul(shapes.offsets.reshape({k, n * kBlendshapeAttributes})).reshape({n, -1});
  PosedGaussians posed;
  posed.means = a.slice(1, 0, 3);
  posed.quats = a.slice(1, 3, 7);
  posed.log_scales = a.slice(1, 7, 10);
  posed.features = a.slice(1, 10, 13).clamp(0, 1);
  posed.opacities = shapes.opacities;
  return posed;
}

bool IsBlendshapeFolder(const fs::path& dir) {
  std::error_code ec;
  return fs::exists(dir / "blendshapes.json", ec);
}

Status ReadGaussianBlendshapes(const fs::path& dir, GaussianBlendshapes* shapes, DatasetOptions* data) {
  nlohmann::json layout;
  HF_RETURN_IF_ERROR(ReadJson(dir / "blendshapes.json", &layout));
  if (layout.value("format", "") != "headforge-gaussian-blendshapes" || layout.value("version", 0) != 1)
    return Status::DataError(dir.string() + "/blendshapes.json is not a version-1 Gaussian blendshape file");
  const int64_t n = layout.value("gaussians", int64_t(0));
  shapes->names = layout.value("expressions", std::vector<std::string>());
  const int64_t k = int64_t(shapes->names.size());
  std::string bytes;
  HF_RETURN_IF_ERROR(ReadFileToString(dir / "blendshapes.bin", &bytes));
  const size_t expected = sizeof(float) * size_t(n * (1 + kBlendshapeAttributes * (1 + k)));
  if (n <= 0 || bytes.size() != expected)
    return Status::DataError(dir.string() + "/blendshapes.bin holds " + std::to_string(bytes.size()) +
                             " bytes where blendshapes.json lays out " + std::to_string(expected) +
                             "; export them again (headforge export --formats blendshapes)");
  const torch::Tensor all = torch::empty({int64_t(bytes.size() / sizeof(float))}, torch::kFloat32);
  std::memcpy(all.data_ptr<float>(), bytes.data(), bytes.size());
  shapes->opacities = all.slice(0, 0, n).clone();
  shapes->neutral = all.slice(0, n, n * (1 + kBlendshapeAttributes)).reshape({n, kBlendshapeAttributes}).clone();
  shapes->offsets = all.slice(0, n * (1 + kBlendshapeAttributes)).reshape({k, n, kBlendshapeAttributes}).clone();
  shapes->pose_condition = torch::tensor(layout.value("pose_condition", std::vector<double>()), torch::kFloat32);
  if (data) FromJson(layout.value("data", nlohmann::json::object()), data);
  return Status::Ok();
}

}  // namespace headforge
