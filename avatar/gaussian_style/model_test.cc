// Numerical hard cases of the gaussian-style model: Gaussians deformed behind
// the camera or onto its plane, riding a mesh with zero-area triangles, and a
// frame whose mask is empty. The render, the loss and every gradient stay
// finite; the scores of an empty mask are set apart rather than averaged in.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <Eigen/Geometry>

#include "avatar/gaussian_style/model.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/metrics/image_metrics.h"
#include "avatar/splat/splat_ops.h"

namespace headforge {
namespace {

constexpr int64_t kExpressions = 4;

GaussianStyleOptions SmallOptions(bool mesh_riding) {
  GaussianStyleOptions o;
  o.feature_channels = 8;
  o.triplane.latent_dim = 8;
  o.triplane.w_dim = 16;
  o.triplane.channels = 8;
  o.triplane.resolution = 8;
  o.triplane.plane_channels = 4;
  o.token_dim = 8;
  o.heads = 2;
  o.ffn_hidden = 16;
  o.deform_hidden = 16;
  o.expressions = kExpressions;
  o.mesh_riding = mesh_riding;
  return o;
}

// A camera 0.5 m in front of the head frame's origin, looking at it (+z).
SplatCamera FrontCamera() {
  SplatCamera c;
  c.cam_from_world = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.5};
  c.fx = c.fy = 60;
  c.cx = c.cy = 23.5;
  c.width = c.height = 48;
  return c;
}

AvatarGaussians RandomGaussians(int64_t n, int64_t channels) {
  AvatarGaussians g;
  g.params.means = (torch::rand({n, 3}) - 0.5) * 0.3;
  g.params.quats = torch::randn({n, 4});
  g.params.log_scales = torch::full({n, 3}, -4.0) + torch::randn({n, 3}) * 0.3;
  g.params.opacity_logits = torch::randn({n});
  g.params.colour_logits = torch::randn({n, channels});
  return g;
}

// Scrambles every weight (the deformer starts at zero: the Gaussians would
// not move) so that the deformation is large.
void ScrambleWeights(GaussianStyle& model, double scale) {
  torch::NoGradGuard no_grad;
  for (torch::Tensor& p : model->parameters()) p.copy_(torch::randn_like(p) * scale);
}

// Renders every channel, takes an L1 + D-SSIM loss against a grey target and
// checks the image, the loss and every gradient.
void ExpectFiniteRenderAndGradients(GaussianStyle& model, AvatarGaussians& g, const PosedGaussians& posed,
                                    const SplatCamera& camera) {
  const SplatRenderResult out = RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities,
                                                posed.features, torch::zeros({posed.features.size(1)}), camera);
  ASSERT_TRUE(torch::isfinite(out.image).all().item<bool>());
  const torch::Tensor rgb = out.image.slice(0, 0, 3);
  const torch::Tensor target = torch::full_like(rgb, 0.5);
  const torch::Tensor loss = 0.8 * (rgb - target).abs().mean() + 0.2 * (1 - Ssim(rgb, target)) + out.image.mean();
  ASSERT_TRUE(std::isfinite(loss.item<double>()));
  loss.backward();
  for (torch::Tensor* t : g.params.All()) {
    ASSERT_TRUE(t->grad().defined());
    EXPECT_TRUE(torch::isfinite(t->grad()).all().item<bool>());
  }
  int with_gradient = 0;
  for (const torch::Tensor& p : model->parameters()) {
    if (!p.grad().defined()) continue;
    EXPECT_TRUE(torch::isfinite(p.grad()).all().item<bool>());
    with_gradient += p.grad().abs().sum().item<double>() > 0;
  }
  EXPECT_GT(with_gradient, 0);  // the networks do learn from this frame
}

TEST(GaussianStyleHardCases, GaussiansDeformedBehindTheCameraStayFinite) {
  torch::manual_seed(7);
  GaussianStyle model(SmallOptions(false), 3);
  ScrambleWeights(model, 0.5);
  AvatarGaussians g = RandomGaussians(300, 8);
  {
    // A third behind the camera (z < -0.5), a few on its plane, one at its centre.
    torch::NoGradGuard no_grad;
    g.params.means.slice(0, 0, 100).select(1, 2).uniform_(-2.0, -0.51);
    g.params.means.slice(0, 100, 110).select(1, 2).fill_(-0.5);
    g.params.means[110].copy_(torch::tensor({0.0, 0.0, -0.5}));
  }
  for (torch::Tensor* t : g.params.All()) t->requires_grad_(true);
  const torch::Tensor condition = torch::rand({kExpressions + 9});
  const PosedGaussians posed = model->Pose(g, condition, 1, nullptr, nullptr, /*deform=*/true);
  // The scrambled deformer moves the Gaussians by centimetres: some cross the camera.
  EXPECT_GT((posed.means - g.params.means).abs().max().item<double>(), 0.01);
  ExpectFiniteRenderAndGradients(model, g, posed, FrontCamera());
}

TEST(GaussianStyleHardCases, RidingZeroAreaTrianglesStaysFinite) {
  torch::manual_seed(8);
  GaussianStyle model(SmallOptions(true), 2);
  ScrambleWeights(model, 0.3);
  // Triangle 0 is sound, 1 has two equal corners, 2 is collinear, 3 collapses to a point.
  const torch::Tensor vertices = torch::tensor({0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.05, 0.0, 0.1, 0.0, 0.0,
                                                0.02, 0.02, 0.01}).view({5, 3});
  const torch::Tensor triangles = torch::tensor({0, 1, 2, 1, 1, 4, 0, 1, 3, 4, 4, 4}, torch::kLong).view({4, 3});
  const TriangleFrames neutral = ComputeTriangleFrames(vertices, triangles);
  const TriangleFrames moved = ComputeTriangleFrames(vertices * 1.1 + 0.01, triangles);
  AvatarGaussians g = RandomGaussians(200, 8);
  g.binding = torch::arange(200, torch::kLong) % 4;
  for (torch::Tensor* t : g.params.All()) t->requires_grad_(true);
  const PosedGaussians posed = model->Pose(g, torch::rand({kExpressions + 9}), 0, &moved, &neutral, true);
  ExpectFiniteRenderAndGradients(model, g, posed, FrontCamera());
}

TEST(GaussianStyleHardCases, AnEmptyMaskIsScoredOverTheWholeFrameOnly) {
  torch::manual_seed(9);
  const torch::Tensor render = torch::rand({3, 32, 32}), image = torch::rand({3, 32, 32});
  const torch::Tensor background = torch::full({3}, 0.5);
  const ViewScores empty = ScoreRender(render, image, torch::zeros({1, 32, 32}), background);
  EXPECT_FALSE(empty.has_head);
  EXPECT_TRUE(std::isfinite(empty.psnr_full));
  // The target is all background: the whole-frame PSNR is the render's against grey.
  const double mse = (render - 0.5).pow(2).mean().item<double>();
  EXPECT_NEAR(empty.psnr_full, -10 * std::log10(mse), 1e-3);

  const torch::Tensor mask = (torch::rand({1, 32, 32}) > 0.5).to(torch::kFloat32);
  const ViewScores head = ScoreRender(render, image, mask, background);
  EXPECT_TRUE(head.has_head);
  const ViewScores mean = MeanScores({empty, head});
  EXPECT_DOUBLE_EQ(mean.psnr_masked, head.psnr_masked);  // the empty mask is not averaged in
  EXPECT_NEAR(mean.psnr_full, (empty.psnr_full + head.psnr_full) / 2, 1e-12);
}

// A head-pose correction moves the Gaussians as Eigen's rotation and
// translation move points, turns their rotations with it, and its gradient
// matches central differences (float64).
TEST(CorrectPose, MovesTheGaussiansRigidlyAndItsGradientMatchesDifferences) {
  torch::manual_seed(3);
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
  PosedGaussians posed;
  posed.means = torch::randn({5, 3}, f64) * 0.1;
  posed.quats = torch::randn({5, 4}, f64);
  posed.log_scales = torch::randn({5, 3}, f64);
  posed.opacities = torch::rand({5}, f64);
  posed.features = torch::rand({5, 3}, f64);
  const torch::Tensor correction = torch::tensor({0.05, -0.02, 0.03, 0.004, -0.002, 0.001}, f64);
  const PosedGaussians moved = CorrectPose(posed, correction);
  const Eigen::Vector3d omega(0.05, -0.02, 0.03), shift(0.004, -0.002, 0.001);
  const Eigen::AngleAxisd turn(omega.norm(), omega.normalized());
  for (int64_t i = 0; i < 5; ++i) {
    const Eigen::Vector3d p(posed.means[i][0].item<double>(), posed.means[i][1].item<double>(),
                            posed.means[i][2].item<double>());
    const Eigen::Vector3d expected = turn * p + shift;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(moved.means[i][k].item<double>(), expected[k], 1e-12) << i;
    // The Gaussian's axes turn with it: R(q') = R(omega) R(q).
    const Eigen::Quaterniond q(posed.quats[i][0].item<double>(), posed.quats[i][1].item<double>(),
                               posed.quats[i][2].item<double>(), posed.quats[i][3].item<double>());
    const Eigen::Quaterniond q2(moved.quats[i][0].item<double>(), moved.quats[i][1].item<double>(),
                                moved.quats[i][2].item<double>(), moved.quats[i][3].item<double>());
    EXPECT_NEAR(q2.norm(), q.norm(), 1e-12);
    const Eigen::Matrix3d expected_axes = turn.toRotationMatrix() * q.normalized().toRotationMatrix();
    EXPECT_LT((q2.normalized().toRotationMatrix() - expected_axes).norm(), 1e-12) << i;
  }
  EXPECT_TRUE(torch::equal(moved.log_scales, posed.log_scales));

  // The gradient of a scalar of the result, at the correction and at zero
  // (where the angle's norm has no derivative of its own).
  const torch::Tensor weights_m = torch::randn({5, 3}, f64), weights_q = torch::randn({5, 4}, f64);
  const auto loss = [&](const torch::Tensor& c) {
    const PosedGaussians m = CorrectPose(posed, c);
    return ((m.means * weights_m).sum() + (m.quats * weights_q).sum());
  };
  for (const torch::Tensor& at : {correction, torch::zeros({6}, f64)}) {
    const torch::Tensor c = at.clone().requires_grad_(true);
    loss(c).backward();
    const torch::Tensor grad = c.grad();
    for (int64_t k = 0; k < 6; ++k) {
      const double h = 1e-6;
      torch::Tensor plus = at.clone(), minus = at.clone();
      plus[k] += h;
      minus[k] -= h;
      const double numeric = (loss(plus).item<double>() - loss(minus).item<double>()) / (2 * h);
      EXPECT_NEAR(grad[k].item<double>(), numeric, 1e-6 * std::max(1.0, std::abs(numeric))) << k;
    }
  }
}

}  // namespace
}  // namespace headforge
