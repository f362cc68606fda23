// The mesh binding against a plain reference, under a similarity of the
// mesh, round trips, degenerate triangles and finite differences.
#include "avatar/gaussian_style/binding.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <Eigen/Geometry>

#include "avatar/tensor_test_util.h"

namespace headforge {
namespace {


// Covariance R diag(s^2) R^T of Gaussians [N].
torch::Tensor Covariance(const torch::Tensor& quats, const torch::Tensor& log_scales) {
  const torch::Tensor q = quats / quats.norm(2, 1, true);
  std::vector<torch::Tensor> out;
  for (int64_t i = 0; i < q.size(0); ++i) {
    const Eigen::Quaterniond e(q[i][0].item<double>(), q[i][1].item<double>(), q[i][2].item<double>(),
                               q[i][3].item<double>());
    const Eigen::Matrix3d r = e.toRotationMatrix();
    Eigen::Vector3d s;
    for (int k = 0; k < 3; ++k) s[k] = std::exp(2 * log_scales[i][k].item<double>());
    const Eigen::Matrix3d c = r * s.asDiagonal() * r.transpose();
    out.push_back(torch::from_blob(const_cast<double*>(c.data()), {3, 3}, kDouble).clone().t());
  }
  return torch::stack(out);
}

TEST(MeshBinding, MatchesAPlainFrameAndFollowsASimilarityOfTheMesh) {
  torch::manual_seed(1);
  const torch::Tensor vertices = torch::randn({5, 3}, kDouble) * 0.05;
  const torch::Tensor triangles = torch::tensor({0, 1, 2, 1, 3, 4, 0, 2, 4}, torch::kLong).view({3, 3});
  const TriangleFrames frames = ComputeTriangleFrames(vertices, triangles);
  // The frame of triangle 1, written out.
  const Eigen::Vector3d a(vertices[1][0].item<double>(), vertices[1][1].item<double>(), vertices[1][2].item<double>());
  const Eigen::Vector3d b(vertices[3][0].item<double>(), vertices[3][1].item<double>(), vertices[3][2].item<double>());
  const Eigen::Vector3d c(vertices[4][0].item<double>(), vertices[4][1].item<double>(), vertices[4][2].item<double>());
  const Eigen::Vector3d x = (b - a).normalized(), z = (b - a).cross(c - a).normalized(), y = z.cross(x);
  const double k = ((b - a).norm() + (c - a).norm() + (c - b).norm()) / 3;
  const torch::Tensor binding = torch::tensor({1, 1, 0, 2}, torch::kLong);
  const torch::Tensor local_means = torch::randn({4, 3}, kDouble), local_quats = torch::randn({4, 4}, kDouble);
  const torch::Tensor local_log_scales = torch::randn({4, 3}, kDouble) * 0.3;
  const BoundGaussians g = ApplyBinding(frames, binding, local_means, local_quats, local_log_scales);
  const Eigen::Vector3d l(local_means[0][0].item<double>(), local_means[0][1].item<double>(),
                          local_means[0][2].item<double>());
  const Eigen::Vector3d expected = (a + b + c) / 3 + k * (x * l.x() + y * l.y() + z * l.z());
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(g.means[0][i].item<double>(), expected[i], 1e-12);
  EXPECT_NEAR(frames.scale[1].item<double>(), k, 1e-12);

  // Rotate, scale and move the whole mesh: the Gaussians follow.
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const torch::Tensor r = torch::from_blob(const_cast<double*>(rot.data()), {3, 3}, kDouble).clone().t();
  const double s = 1.7;
  const torch::Tensor t = torch::tensor({0.1, -0.3, 0.25}, kDouble);
  const TriangleFrames moved = ComputeTriangleFrames(s * torch::matmul(vertices, r.t()) + t, triangles);
  const BoundGaussians h = ApplyBinding(moved, binding, local_means, local_quats, local_log_scales);
  EXPECT_TRUE(torch::allclose(h.means, s * torch::matmul(g.means, r.t()) + t, 1e-10, 1e-12));
  const torch::Tensor cov = Covariance(g.quats, g.log_scales), cov_moved = Covariance(h.quats, h.log_scales);
  EXPECT_TRUE(torch::allclose(cov_moved, s * s * torch::matmul(torch::matmul(r, cov), r.t()), 1e-10, 1e-14));

  // Back to local values.
  const BoundGaussians back = ToLocal(moved, binding, h.means, h.quats, h.log_scales);
  EXPECT_TRUE(torch::allclose(back.means, local_means, 1e-10, 1e-12));
  EXPECT_TRUE(torch::allclose(back.log_scales, local_log_scales, 1e-10, 1e-12));
  EXPECT_TRUE(torch::allclose(Covariance(back.quats, back.log_scales), Covariance(local_quats, local_log_scales),
                              1e-10, 1e-12));
}

TEST(MeshBinding, RotationsBackToQuaternions) {
  torch::manual_seed(2);
  torch::Tensor q = torch::randn({200, 4}, kDouble);
  q.slice(0, 0, 3) = torch::tensor({0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1e-9, 1e-7, 0.0, 0.0, 1.0}, kDouble).view({3, 4});
  q = q / q.norm(2, 1, true);
  q = q * torch::where(q.select(1, 0) < 0, -1.0, 1.0).unsqueeze(1);  // w >= 0
  std::vector<torch::Tensor> rotations;
  for (int64_t i = 0; i < q.size(0); ++i) {
    const Eigen::Matrix3d m =
        Eigen::Quaterniond(q[i][0].item<double>(), q[i][1].item<double>(), q[i][2].item<double>(), q[i][3].item<double>())
            .toRotationMatrix();
    rotations.push_back(torch::from_blob(const_cast<double*>(m.data()), {3, 3}, kDouble).clone().t());
  }
  const torch::Tensor back = RotationToQuat(torch::stack(rotations));
  // Equal up to sign (half-turns have w = 0 either way).
  const torch::Tensor dot = (back * q).sum(1).abs();
  EXPECT_GT(dot.min().item<double>(), 1 - 1e-9);
}

TEST(MeshBinding, DegenerateTrianglesStayFinite) {
  const torch::Tensor vertices = torch::tensor({0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.5, 0.5, 0.0}, kDouble)
                                     .view({4, 3});
  // Collinear, a repeated vertex, all three the same, and a good one.
  const torch::Tensor triangles = torch::tensor({0, 1, 2, 0, 0, 3, 1, 1, 1, 0, 1, 3}, torch::kLong).view({4, 3});
  const TriangleFrames frames = ComputeTriangleFrames(vertices, triangles);
  for (const torch::Tensor& t : {frames.origin, frames.rotation, frames.quat, frames.scale})
    EXPECT_TRUE(torch::isfinite(t).all().item<bool>());
  EXPECT_TRUE(torch::allclose(frames.rotation[2], torch::eye(3, kDouble)));
  EXPECT_GE(frames.scale.min().item<double>(), 1e-6);
  const torch::Tensor binding = torch::tensor({0, 1, 2, 3}, torch::kLong);
  const torch::Tensor local = torch::randn({4, 3}, kDouble).requires_grad_(true);
  const BoundGaussians g = ApplyBinding(frames, binding, local, torch::randn({4, 4}, kDouble), torch::zeros({4, 3}, kDouble));
  (g.means.sum() + g.log_scales.sum()).backward();
  EXPECT_TRUE(torch::isfinite(g.means).all().item<bool>());
  EXPECT_TRUE(torch::isfinite(g.log_scales).all().item<bool>());
  EXPECT_TRUE(torch::isfinite(local.grad()).all().item<bool>());
}

TEST(MeshBinding, GradientsMatchFiniteDifferences) {
  torch::manual_seed(3);
  const torch::Tensor vertices = torch::randn({4, 3}, kDouble) * 0.05;
  const torch::Tensor triangles = torch::tensor({0, 1, 2, 1, 2, 3}, torch::kLong).view({2, 3});
  const TriangleFrames frames = ComputeTriangleFrames(vertices, triangles);
  const torch::Tensor binding = torch::tensor({0, 1, 1}, torch::kLong);
  const torch::Tensor means = torch::randn({3, 3}, kDouble), quats = torch::randn({3, 4}, kDouble),
                      log_scales = torch::randn({3, 3}, kDouble);
  const torch::Tensor r_means = torch::randn({3, 3}, kDouble), r_quats = torch::randn({3, 4}, kDouble),
                      r_scales = torch::randn({3, 3}, kDouble);
  auto loss = [&](const torch::Tensor& m, const torch::Tensor& q, const torch::Tensor& s) {
    const BoundGaussians g = ApplyBinding(frames, binding, m, q, s);
    return (g.means * r_means).sum() + (g.quats * r_quats).sum() + (g.log_scales * r_scales).sum();
  };
  std::vector<torch::Tensor> inputs = {means.clone().requires_grad_(true), quats.clone().requires_grad_(true),
                                       log_scales.clone().requires_grad_(true)};
  const auto grads = torch::autograd::grad({loss(inputs[0], inputs[1], inputs[2])}, inputs);
  const double h = 1e-6;
  for (size_t which = 0; which < 3; ++which) {
    for (int64_t i = 0; i < inputs[which].numel(); ++i) {
      std::vector<torch::Tensor> plus = {means.clone(), quats.clone(), log_scales.clone()};
      std::vector<torch::Tensor> minus = {means.clone(), quats.clone(), log_scales.clone()};
      plus[which].view(-1)[i] += h;
      minus[which].view(-1)[i] -= h;
      const double numeric =
          (loss(plus[0], plus[1], plus[2]).item<double>() - loss(minus[0], minus[1], minus[2]).item<double>()) / (2 * h);
      EXPECT_NEAR(grads[which].view(-1)[i].item<double>(), numeric, 1e-7 * (1 + std::abs(numeric)))
          << "input " << which << " entry " << i;
    }
  }
}

// The frames of the bound triangles alone (as a posed avatar takes them) are
// the whole mesh's at those rows to the bit, in float32 as trained, with a
// degenerate triangle among them; the rows no Gaussian reads are zero.
TEST(MeshBinding, TheBoundTrianglesFramesAreTheWholeMeshsRows) {
  torch::manual_seed(3);
  const int64_t v = 400, t = 700;
  torch::Tensor vertices = torch::randn({v, 3}) * 0.1;
  torch::Tensor triangles = torch::randint(0, v, {t, 3}, torch::kLong);
  triangles[5][1] = triangles[5][0];  // a zero edge
  const torch::Tensor wanted = torch::tensor({5, 17, 17, 3, 699, 250, 5, 0}, torch::kLong);
  const TriangleFrames all = ComputeTriangleFrames(vertices, triangles);
  const TriangleFrames some = ComputeTriangleFrames(vertices, triangles, wanted);
  for (const auto& [whole, part] : {std::pair(all.origin, some.origin), std::pair(all.rotation, some.rotation),
                                    std::pair(all.quat, some.quat), std::pair(all.scale, some.scale)}) {
    ASSERT_EQ(whole.sizes(), part.sizes());
    EXPECT_TRUE(torch::equal(whole.index_select(0, wanted), part.index_select(0, wanted)));
    EXPECT_EQ(part.index_select(0, torch::tensor({1, 2, 4, 698}, torch::kLong)).abs().sum().item<float>(), 0.0f);
  }
  // What a Gaussian bound to them gets is then the same too.
  const torch::Tensor means = torch::randn({8, 3}), quats = torch::randn({8, 4}), scales = torch::randn({8, 3});
  const BoundGaussians a = ApplyBinding(all, wanted, means, quats, scales);
  const BoundGaussians b = ApplyBinding(some, wanted, means, quats, scales);
  EXPECT_TRUE(torch::equal(a.means, b.means));
  EXPECT_TRUE(torch::equal(a.quats, b.quats));
  EXPECT_TRUE(torch::equal(a.log_scales, b.log_scales));
}

}  // namespace
}  // namespace headforge
