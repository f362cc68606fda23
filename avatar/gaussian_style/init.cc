// The avatar's starting Gaussians, sampled on the tracked identity's mesh.
#include <torch/torch.h>

#include <Eigen/Geometry>

#include <cmath>

#include "avatar/gaussian_style/trainer.h"
#include "reconstruction/mesh_utils.h"

namespace headforge {
namespace {

// What the Gaussians start on: every visible part of the head, not the
// eyelashes, the eyes' occlusion and tear shells, or the blend strips.
const char* const kSampledRegions[] = {"face",  "head_and_neck",   "eyeball_left", "eyeball_right",
                                       "teeth", "gums_and_tongue", "mouth_socket"};

// The mean colour each point shows in up to `views` training views that face
// it (its normal toward the camera, inside the image and the mask); grey
// where none does.
Eigen::Matrix3Xf SeenColours(const AvatarDataset& data, const Eigen::Matrix3Xf& points, const Eigen::Matrix3Xf& normals,
                             int views) {
  Eigen::Matrix3Xf sum = Eigen::Matrix3Xf::Zero(3, points.cols());
  Eigen::VectorXf count = Eigen::VectorXf::Zero(points.cols());
  const int n = std::min<int>(views, int(data.train.size()));
  for (int k = 0; k < n; ++k) {
    const AvatarView& view = data.train[size_t(k) * data.train.size() / n];
    const auto& m = view.view.cam_from_world;
    Eigen::Matrix3f r;
    Eigen::Vector3f t;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) r(i, j) = float(m[4 * i + j]);
      t[i] = float(m[4 * i + 3]);
    }
    const torch::Tensor image = view.image.contiguous(), mask = view.mask.contiguous();
    const float* rgb = image.data_ptr<float>();
    const float* inside = mask.data_ptr<float>();
    const int w = view.view.width, h = view.view.height;
    for (Eigen::Index p = 0; p < points.cols(); ++p) {
      const Eigen::Vector3f c = r * points.col(p) + t;
      if (c.z() <= 0 || (r * normals.col(p)).dot(c) >= 0) continue;
      const int u = int(std::lround(view.view.fx * c.x() / c.z() + view.view.cx));
      const int v = int(std::lround(view.view.fy * c.y() / c.z() + view.view.cy));
      if (u < 0 || v < 0 || u >= w || v >= h || inside[v * w + u] < 0.5f) continue;
      for (int ch = 0; ch < 3; ++ch) sum(ch, p) += rgb[(ch * h + v) * w + u];
      count[p] += 1;
    }
  }
  Eigen::Matrix3Xf colours = Eigen::Matrix3Xf::Constant(3, points.cols(), 0.5f);
  for (Eigen::Index p = 0; p < points.cols(); ++p)
    if (count[p] > 0) colours.col(p) = sum.col(p) / count[p];
  return colours;
}

}  // namespace

Status InitGaussians(const AvatarDataset& data, const TrainOptions& options, const GaussianStyleAvatar& avatar,
                     AvatarGaussians* gaussians) {
  std::vector<int> chosen;  // model triangle indices
  for (const char* name : kSampledRegions) {
    const auto part = data.mesh_parts.find(name);
    if (part != data.mesh_parts.end())
      for (int t = part->second.first; t <= part->second.second; ++t) chosen.push_back(t);
  }
  const torch::Tensor model_triangles = data.triangles.to(torch::kInt64).contiguous().cpu();
  if (chosen.empty())
    for (int t = 0; t < int(model_triangles.size(0)); ++t) chosen.push_back(t);
  Eigen::Matrix3Xi triangles(3, Eigen::Index(chosen.size()));
  const auto corners = model_triangles.accessor<int64_t, 2>();
  for (size_t i = 0; i < chosen.size(); ++i)
    for (int k = 0; k < 3; ++k) triangles(k, Eigen::Index(i)) = int(corners[chosen[i]][k]);
  const torch::Tensor identity = data.identity_vertices.contiguous().cpu();
  const Eigen::Matrix3Xf vertices = Eigen::Map<const Eigen::Matrix3Xf>(identity.data_ptr<float>(), 3, identity.size(0));
  SurfaceSamples samples;
  HF_RETURN_IF_ERROR(SampleSurface(vertices, triangles, options.gaussian_style.init_gaussians,
                                   uint64_t(options.seed) + 17, &samples)
                         .WithContext("initial Gaussians"));
  const Eigen::Matrix3Xf points = SamplePositions(samples, vertices, triangles);
  Eigen::Matrix3Xf normals(3, points.cols());
  double area = 0;
  for (int t = 0; t < triangles.cols(); ++t) {
    const Eigen::Vector3f a = vertices.col(triangles(0, t)), b = vertices.col(triangles(1, t)), c = vertices.col(triangles(2, t));
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  for (int s = 0; s < samples.size(); ++s) {
    const int t = samples.triangles[s];
    const Eigen::Vector3f a = vertices.col(triangles(0, t)), b = vertices.col(triangles(1, t)), c = vertices.col(triangles(2, t));
    normals.col(s) = (b - a).cross(c - a).normalized();
  }
  const Eigen::Matrix3Xf colours = SeenColours(data, points, normals, 8);
  const int64_t n = samples.size();
  const double spacing = std::sqrt(area / std::max<int64_t>(n, 1));
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32);
  GaussianParams& p = gaussians->params;
  torch::Tensor means = torch::from_blob(const_cast<float*>(points.data()), {n, 3}, opts).clone();
  torch::Tensor quats = torch::zeros({n, 4}, opts);
  quats.select(1, 0).fill_(1.0);
  torch::Tensor log_scales = torch::full({n, 3}, std::log(0.7 * spacing), opts);
  if (avatar.model->options().mesh_riding) {
    std::vector<int64_t> bound(static_cast<size_t>(n));
    for (int64_t s = 0; s < n; ++s) bound[size_t(s)] = chosen[size_t(samples.triangles[s])];
    gaussians->binding = torch::tensor(bound, torch::kInt64);
    const BoundGaussians local = ToLocal(avatar.neutral, gaussians->binding, means, quats, log_scales);
    means = local.means;
    quats = local.quats;
    log_scales = local.log_scales;
  }
  p.means = means;
  p.quats = quats;
  p.log_scales = log_scales;
  p.opacity_logits = torch::full({n}, std::log(0.1 / 0.9), opts);
  p.colour_logits = torch::zeros({n, int64_t(options.feature_channels)}, opts);
  const torch::Tensor rgb = torch::from_blob(const_cast<float*>(colours.data()), {n, 3}, opts).clone();
  p.colour_logits.slice(1, 0, 3).copy_(torch::logit(rgb.clamp(0.02, 0.98)));
  return Status::Ok();
}

}  // namespace headforge
