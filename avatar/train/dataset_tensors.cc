// The parts of the avatar dataset that need LibTorch and Eigen alone (a
// LibTorch-only build trains from a pack with them; dataset_pack.h).
#include <torch/torch.h>

#include <cmath>
#include <map>
#include <vector>

#include <Eigen/Geometry>

#include "avatar/train/dataset.h"
#include "avatar/train/view_camera.h"

namespace headforge {

torch::Tensor AvatarDataset::Vertices(const torch::Tensor& expression) const {
  return identity_vertices + torch::matmul(expression_basis, expression.to(expression_basis.dtype())).view({-1, 3});
}

torch::Tensor AvatarDataset::Vertices(const std::vector<torch::Tensor>& expressions) const {
  const int64_t n = int64_t(expressions.size());
  if (n == 0) return torch::empty({0, identity_vertices.size(0), 3}, identity_vertices.options());
  // [3V, E] x [E, N]: the basis read once for every row, where N products
  // with one vector each read it N times (16 MB for the ICT model).
  const torch::Tensor weights = torch::stack(expressions, 1).to(expression_basis.dtype());
  return identity_vertices.unsqueeze(0) + torch::matmul(expression_basis, weights).t().reshape({n, -1, 3});
}

torch::Tensor AvatarDataset::Vertices(const AvatarView& view) const {
  if (view.vertices.defined()) return view.vertices;
  return Vertices(view.condition.slice(0, 0, int64_t(expression_names.size())));
}

void AttachViewVertices(AvatarDataset* data) {
  const int64_t e = int64_t(data->expression_names.size());
  // A view of each frame still without its mesh; one for all when every
  // view carries one state of the head.
  const auto key = [&](const AvatarView& view) { return data->one_state ? 0 : view.frame; };
  std::map<int, AvatarView*> first;
  std::vector<AvatarView*> missing;
  for (auto* list : {&data->train, &data->test, &data->validation})
    for (AvatarView& view : *list)
      if (!view.vertices.defined()) {
        first.emplace(key(view), &view);
        missing.push_back(&view);
      }
  if (missing.empty()) return;
  std::vector<torch::Tensor> expressions;
  std::map<int, int64_t> row;
  for (const auto& [frame, view] : first) {
    row[frame] = int64_t(expressions.size());
    expressions.push_back(view->condition.slice(0, 0, e));
  }
  const torch::Tensor all = data->Vertices(expressions).contiguous();
  for (AvatarView* view : missing) view->vertices = all[row.at(key(*view))];
}

std::string AvatarDataset::HeldOutText() const {
  int held = 0;
  for (int f = 0; f < num_frames; ++f) held += HeldOut(f);
  if (holdout_every == 0) return "the last " + std::to_string(held) + " of " + std::to_string(num_frames);
  return "one frame in " + std::to_string(holdout_every) + " from frame " + std::to_string(holdout_every / 2) + " (" +
         std::to_string(held) + " of " + std::to_string(num_frames) + ")";
}

torch::Tensor ImageFromBytes(const torch::Tensor& bytes) { return bytes.to(torch::kFloat32).div(255.0).contiguous(); }

torch::Tensor PoseCondition(const double rotation[9], const double translation[3]) {
  // Row-major rotation: its first two columns, then the translation.
  return torch::tensor({rotation[0], rotation[3], rotation[6], rotation[1], rotation[4], rotation[7], translation[0],
                        translation[1], translation[2]},
                       torch::kFloat32);
}

SplatCamera OrbitCamera(const SplatCamera& camera, double yaw_deg, double pitch_deg) {
  const double yaw = yaw_deg * M_PI / 180, pitch = pitch_deg * M_PI / 180;
  // world_from_cam' = O world_from_cam, so cam_from_world' = cam_from_world O^T,
  // with O turning +z toward +x (yaw) and toward +y (pitch).
  const Eigen::Matrix3d o = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  // Turning the camera about the origin keeps its translation.
  Eigen::Isometry3d turned = CameraPose(camera);
  turned.linear() = turned.linear() * o.transpose();
  SplatCamera out = camera;
  SetCameraPose(turned, &out);
  return out;
}

}  // namespace headforge
