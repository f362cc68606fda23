#include "avatar/gaussian_style/binding.h"

#include <torch/torch.h>

namespace headforge {

torch::Tensor QuatMultiply(const torch::Tensor& a, const torch::Tensor& b) {
  const torch::Tensor aw = a.select(-1, 0), ax = a.select(-1, 1), ay = a.select(-1, 2), az = a.select(-1, 3);
  const torch::Tensor bw = b.select(-1, 0), bx = b.select(-1, 1), by = b.select(-1, 2), bz = b.select(-1, 3);
  return torch::stack({aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                       aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw},
                      -1);
}

torch::Tensor RotationToQuat(const torch::Tensor& r) {
  auto at = [&](int i, int j) { return r.select(-2, i).select(-1, j); };
  // Each component's magnitude from the diagonal, its sign from the
  // off-diagonal differences (w taken non-negative).
  const torch::Tensor w = 0.5 * (1 + at(0, 0) + at(1, 1) + at(2, 2)).clamp_min(0).sqrt();
  const torch::Tensor x = 0.5 * (1 + at(0, 0) - at(1, 1) - at(2, 2)).clamp_min(0).sqrt();
  const torch::Tensor y = 0.5 * (1 - at(0, 0) + at(1, 1) - at(2, 2)).clamp_min(0).sqrt();
  const torch::Tensor z = 0.5 * (1 - at(0, 0) - at(1, 1) + at(2, 2)).clamp_min(0).sqrt();
  auto sign = [](const torch::Tensor& t) { return torch::where(t < 0, -torch::ones_like(t), torch::ones_like(t)); };
  const torch::Tensor q = torch::stack({w, x * sign(at(2, 1) - at(1, 2)), y * sign(at(0, 2) - at(2, 0)),
                                        z * sign(at(1, 0) - at(0, 1))},
                                       -1);
  return q / q.norm(2, -1, true).clamp_min(1e-12);
}

TriangleFrames ComputeTriangleFrames(const torch::Tensor& vertices, const torch::Tensor& triangles) {
  const torch::Tensor a = vertices.index_select(0, triangles.select(1, 0));
  const torch::Tensor b = vertices.index_select(0, triangles.select(1, 1));
  const torch::Tensor c = vertices.index_select(0, triangles.select(1, 2));
  TriangleFrames f;
  f.origin = (a + b + c) / 3;
  const torch::Tensor e0 = b - a, e1 = c - a;
  const torch::Tensor normal = torch::cross(e0, e1, 1);
  const torch::Tensor e0_len = e0.norm(2, 1, true), n_len = normal.norm(2, 1, true);
  // Degenerate when an edge or the area vanishes against the triangle's size.
  const torch::Tensor size = (e0_len + e1.norm(2, 1, true) + (c - b).norm(2, 1, true)) / 3;
  const torch::Tensor good = (n_len > 1e-8 * size.pow(2)) & (e0_len > 1e-6 * size) & (size > 1e-9);
  const auto opts = vertices.options();
  const torch::Tensor x_axis =
      torch::where(good, e0 / e0_len.clamp_min(1e-30), torch::tensor({1.0, 0.0, 0.0}, opts).expand_as(e0));
  const torch::Tensor z_axis =
      torch::where(good, normal / n_len.clamp_min(1e-30), torch::tensor({0.0, 0.0, 1.0}, opts).expand_as(e0));
  const torch::Tensor y_axis = torch::cross(z_axis, x_axis, 1);
  f.rotation = torch::stack({x_axis, y_axis, z_axis}, 2);  // columns
  f.quat = RotationToQuat(f.rotation);
  f.scale = size.squeeze(1).clamp_min(1e-6);
  return f;
}

TriangleFrames ComputeTriangleFrames(const torch::Tensor& vertices, const torch::Tensor& triangles,
                                     const torch::Tensor& wanted) {
  const torch::Tensor rows = std::get<0>(at::_unique(wanted, /*sorted=*/true));
  const TriangleFrames some = ComputeTriangleFrames(vertices, triangles.index_select(0, rows));
  const int64_t t = triangles.size(0);
  auto spread = [&](const torch::Tensor& values) {
    std::vector<int64_t> shape = values.sizes().vec();
    shape[0] = t;
    return torch::zeros(shape, values.options()).index_copy_(0, rows, values);
  };
  return {spread(some.origin), spread(some.rotation), spread(some.quat), spread(some.scale)};
}

BoundGaussians ApplyBinding(const TriangleFrames& frames, const torch::Tensor& binding,
                            const torch::Tensor& local_means, const torch::Tensor& local_quats,
                            const torch::Tensor& local_log_scales) {
  const torch::Tensor r = frames.rotation.index_select(0, binding);  // [N, 3, 3]
  const torch::Tensor k = frames.scale.index_select(0, binding).unsqueeze(1);
  BoundGaussians g;
  g.means = frames.origin.index_select(0, binding) + k * torch::matmul(r, local_means.unsqueeze(2)).squeeze(2);
  g.quats = QuatMultiply(frames.quat.index_select(0, binding), local_quats);
  g.log_scales = local_log_scales + k.log();
  return g;
}

BoundGaussians ToLocal(const TriangleFrames& frames, const torch::Tensor& binding, const torch::Tensor& means,
                       const torch::Tensor& quats, const torch::Tensor& log_scales) {
  const torch::Tensor r = frames.rotation.index_select(0, binding);
  const torch::Tensor k = frames.scale.index_select(0, binding).unsqueeze(1);
  const torch::Tensor q = frames.quat.index_select(0, binding);
  const torch::Tensor conjugate = q * torch::tensor({1.0, -1.0, -1.0, -1.0}, q.options());
  BoundGaussians g;
  g.means = torch::matmul(r.transpose(1, 2), (means - frames.origin.index_select(0, binding)).unsqueeze(2)).squeeze(2) / k;
  g.quats = QuatMultiply(conjugate, quats);
  g.log_scales = log_scales - k.log();
  return g;
}

}  // namespace headforge
