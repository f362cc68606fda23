// The gan-avatar model's pieces: the generator's render (rays that miss the
// head's box show the background and pass no gradient; rays that meet it
// reach every network), the discriminator's camera conditioning against its
// projection formula, adaptive augmentation keeping stacked channels
// registered, ADA's controller, the camera condition, and the comparison of
// driving expressions with those read back from renders.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <vector>

#include "avatar/gan_avatar/expression_mapping.h"
#include "avatar/gan_avatar/model.h"
#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"

namespace headforge {
namespace {

GanAvatarOptions TinyOptions() {
  GanAvatarOptions o;
  o.z_dim = 8;
  o.w_dim = 16;
  o.synthesis_channels = 8;
  o.plane_resolution = 8;
  o.plane_channels = 4;
  o.decoder_hidden = 8;
  o.feature_channels = 6;
  o.coarse_samples = 6;
  o.fine_samples = 6;
  o.box.min = {-0.1, -0.12, -0.1};
  o.box.max = {0.1, 0.1, 0.12};
  return o;
}

// A camera 0.6 m in front of the head frame's origin, looking at it (+z of
// the head toward the camera), `yaw` turning it about the head's y axis.
SplatCamera FrontCamera(int size, double yaw = 0) {
  SplatCamera c;
  c.width = c.height = size;
  c.fx = c.fy = 1.6 * size;
  c.cx = c.cy = (size - 1) / 2.0;
  // cam_from_head: the camera's axes (x right, y down, z into the scene).
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  // The camera at (0.6 sin, 0, 0.6 cos) looking at the origin, y down, x = y cross z.
  const double ex[3] = {cy, 0, -sy}, ey[3] = {0, -1, 0}, ez[3] = {-sy, 0, -cy};
  const double centre[3] = {0.6 * sy, 0, 0.6 * cy};
  const double* rows[3] = {ex, ey, ez};
  for (int r = 0; r < 3; ++r) {
    double t = 0;
    for (int k = 0; k < 3; ++k) {
      c.cam_from_world[size_t(4 * r + k)] = rows[r][k];
      t -= rows[r][k] * centre[k];
    }
    c.cam_from_world[size_t(4 * r + 3)] = t;
  }
  return c;
}

TEST(GanGenerator, RaysThatMissTheBoxShowTheBackground) {
  torch::manual_seed(2);
  GanGenerator g(TinyOptions());
  // The box spans 0.2 m at 0.6 m: with fx = 1.6 px per unit it covers the
  // middle third of the image; the corners' rays miss it.
  const SplatCamera camera = FrontCamera(12);
  const torch::Tensor w = g->Map(torch::randn({1, 8}));
  const GanRender out = g->Render(w, {camera}, 24, 24, 0.25, nullptr);
  ASSERT_EQ(out.raw.sizes(), (std::vector<int64_t>{1, 3, 12, 12}));
  ASSERT_EQ(out.image.sizes(), (std::vector<int64_t>{1, 3, 24, 24}));
  ASSERT_EQ(out.features.size(1), 6);
  EXPECT_EQ(out.opacity[0][0][0][0].item<double>(), 0);
  EXPECT_NEAR(out.raw[0][1][0][0].item<double>(), 0.25, 1e-7);
  EXPECT_GT(out.opacity[0][0][6][6].item<double>(), 0.05);
  EXPECT_TRUE(torch::isfinite(out.image).all().item<bool>());

  // A corner pixel's raw colour has no gradient; the centre's reaches the
  // mapping, the planes' synthesis and the decoder.
  auto grads = [&](int64_t y, int64_t x) {
    g->zero_grad();
    const torch::Tensor w2 = g->Map(torch::ones({1, 8}));
    g->Render(w2, {camera}, 24, 24, 0.25, nullptr).raw[0].select(1, y).select(1, x).sum().backward();
    double total = 0;
    for (const auto& p : g->named_parameters())
      if (p.key().rfind("super_resolution", 0) != 0 && p.key().rfind("to_rgb", 0) != 0 && p.value().grad().defined())
        total += p.value().grad().abs().sum().item<double>();
    return total;
  };
  EXPECT_EQ(grads(0, 0), 0);
  EXPECT_GT(grads(6, 6), 0);
  for (const auto& p : g->named_parameters()) {
    if (p.key().rfind("planes.mapping", 0) == 0 || p.key().rfind("decoder", 0) == 0) {
      EXPECT_TRUE(p.value().grad().defined() && p.value().grad().abs().sum().item<double>() > 0) << p.key();
    }
  }
}

TEST(GanGenerator, SameLatentAndCameraGiveTheSameImageAndTheCameraMatters) {
  torch::manual_seed(3);
  GanGenerator g(TinyOptions());
  torch::NoGradGuard no_grad;
  const torch::Tensor w = g->Map(torch::randn({2, 8}));
  const SplatCamera front = FrontCamera(8), side = FrontCamera(8, 1.2);
  const GanRender a = g->Render(w, {front, side}, 16, 16, 0.5, nullptr);
  const GanRender b = g->Render(w, {front, side}, 16, 16, 0.5, nullptr);
  EXPECT_TRUE(torch::equal(a.image, b.image));
  const GanRender swapped = g->Render(w, {side, front}, 16, 16, 0.5, nullptr);
  EXPECT_GT((swapped.raw - a.raw).abs().max().item<double>(), 1e-4);
  // Jittered depths come from the generator given: the same state, the same image.
  at::Generator j1 = at::detail::createCPUGenerator(5), j2 = at::detail::createCPUGenerator(5);
  EXPECT_TRUE(torch::equal(g->Render(w, {front, side}, 16, 16, 0.5, &j1).image,
                           g->Render(w, {front, side}, 16, 16, 0.5, &j2).image));
}

TEST(GanGenerator, ABatchRendersAsItsSamplesDoOneByOne) {
  // The batch's rays go through the volume render together, each sample's
  // points on its own planes: the same images, and the same gradients, as
  // rendering the samples one at a time.
  torch::manual_seed(6);
  GanGenerator g(TinyOptions());
  const torch::Tensor z = torch::randn({3, 8});
  const std::vector<SplatCamera> cameras = {FrontCamera(10), FrontCamera(10, 0.7), FrontCamera(10, -2.5)};
  g->zero_grad();
  const GanRender batch = g->Render(g->Map(z), cameras, 20, 20, 0.5, nullptr);
  batch.image.square().sum().backward();
  std::vector<torch::Tensor> batch_grads;
  for (const torch::Tensor& p : g->parameters()) batch_grads.push_back(p.grad().clone());
  g->zero_grad();
  for (int64_t b = 0; b < 3; ++b) {
    const GanRender one = g->Render(g->Map(z.narrow(0, b, 1)), {cameras[size_t(b)]}, 20, 20, 0.5, nullptr);
    EXPECT_TRUE(torch::allclose(one.image, batch.image.narrow(0, b, 1), 1e-5, 1e-6)) << b;
    EXPECT_TRUE(torch::allclose(one.opacity, batch.opacity.narrow(0, b, 1), 1e-5, 1e-6)) << b;
    one.image.square().sum().backward();
  }
  size_t i = 0;
  for (const torch::Tensor& p : g->parameters()) {
    const torch::Tensor& want = p.grad();
    EXPECT_TRUE(torch::allclose(batch_grads[i], want, 1e-4, 1e-5 * (1 + want.abs().max().item<double>()))) << i;
    ++i;
  }
  // A batch whose cameras differ in size is refused, not rendered wrong.
  EXPECT_THROW(g->Render(g->Map(z.narrow(0, 0, 2)), {FrontCamera(10), FrontCamera(12)}, 20, 20, 0.5, nullptr),
               c10::Error);
}

TEST(GanDiscriminator, TheCameraEntersByProjection) {
  // logit(x, c) - logit(x, c') = <embed(c) - embed(c'), h(x)> / sqrt(D),
  // with h the discriminator's final feature; unconditional ignores c.
  torch::manual_seed(4);
  nn::DiscriminatorOptions o;
  o.in_channels = 6;
  o.resolution = 16;
  o.channels = 8;
  o.max_channels = 16;
  o.condition_dim = 16;
  nn::Discriminator d(o);
  d->to(torch::kFloat64);
  const torch::Tensor x = torch::rand({3, 6, 16, 12}, torch::kFloat64);
  const torch::Tensor c1 = torch::randn({3, 16}, torch::kFloat64), c2 = torch::randn({3, 16}, torch::kFloat64);
  const torch::Tensor l1 = d->forward(x, c1), l2 = d->forward(x, c2);
  ASSERT_EQ(l1.sizes(), (std::vector<int64_t>{3}));
  EXPECT_GT((l1 - l2).abs().min().item<double>(), 1e-6);
  const torch::Tensor h = d->Features(x).back();
  ASSERT_EQ(h.size(1), 16);
  // The embedding is the only module taking c: recover it from the difference.
  torch::Tensor e1, e2;
  for (const auto& m : d->named_children())
    if (m.key() == "embed") {
      e1 = m.value()->as<nn::Mlp>()->forward(c1);
      e2 = m.value()->as<nn::Mlp>()->forward(c2);
    }
  ASSERT_TRUE(e1.defined());
  const torch::Tensor expected = ((e1 - e2) * h).sum(1) / 4.0;
  EXPECT_NEAR((l1 - l2 - expected).abs().max().item<double>(), 0, 1e-12);
  // The gradient reaches the condition.
  const torch::Tensor c = c1.clone().requires_grad_(true);
  d->forward(x, c).sum().backward();
  EXPECT_GT(c.grad().abs().sum().item<double>(), 0);

  o.condition_dim = 0;
  nn::Discriminator plain(o);
  EXPECT_EQ(plain->forward(x.to(torch::kFloat32)).sizes(), (std::vector<int64_t>{3}));
}

TEST(GanAugment, StackedChannelsStayRegistered) {
  torch::manual_seed(5);
  const torch::Tensor image = torch::rand({4, 3, 20, 16});
  // A UV-like map: each pixel's own coordinates.
  const torch::Tensor u = torch::linspace(0, 1, 16).view({1, 1, 1, 16}).expand({4, 1, 20, 16});
  const torch::Tensor v = torch::linspace(0, 1, 20).view({1, 1, 20, 1}).expand({4, 1, 20, 16});
  const torch::Tensor uv = torch::cat({u, v}, 1);
  nn::AugmentOptions options;
  at::Generator g0 = at::detail::createCPUGenerator(1);
  EXPECT_TRUE(torch::equal(nn::Augment(image, 0.0, 3, g0), image));  // p = 0: untouched

  // p = 1: every transform on every sample. The same image twice (no colour
  // transform) comes out the same twice.
  at::Generator g1 = at::detail::createCPUGenerator(2);
  const torch::Tensor twice = nn::Augment(torch::cat({image, image}, 1), 1.0, 0, g1, options);
  EXPECT_TRUE(torch::allclose(twice.narrow(1, 0, 3), twice.narrow(1, 3, 3), 0, 1e-6));
  EXPECT_GT((twice.narrow(1, 0, 3) - image).abs().mean().item<double>(), 0.05);  // it did transform
  // The UV channels beside a colour image get the image's geometric
  // transform: the same as the UV map augmented alone with the same draws,
  // and untouched by the colour transforms.
  at::Generator g2 = at::detail::createCPUGenerator(3), g3 = at::detail::createCPUGenerator(3);
  const torch::Tensor stacked = nn::Augment(torch::cat({image, uv}, 1), 1.0, 3, g2, options);
  const torch::Tensor alone = nn::Augment(torch::cat({torch::zeros_like(image), uv}, 1), 1.0, 0, g3, options);
  EXPECT_TRUE(torch::allclose(stacked.narrow(1, 3, 2), alone.narrow(1, 3, 2), 0, 1e-6));
  // Reflection padding keeps the UV values within the map's range.
  EXPECT_GE(stacked.narrow(1, 3, 2).min().item<double>(), -1e-6);
  EXPECT_LE(stacked.narrow(1, 3, 2).max().item<double>(), 1 + 1e-6);
}

TEST(GanAugment, AdaRaisesPWhileTheDiscriminatorIsSureOfTheReals) {
  nn::AdaController ada(0.6, 2, 100);
  for (int i = 0; i < 10; ++i) ada.Observe(torch::ones({5}));
  EXPECT_NEAR(ada.p(), 0.5, 1e-12);  // 5 updates of 10 images / 100
  EXPECT_NEAR(ada.rt(), 1.0, 1e-12);
  const std::vector<double> state = ada.State();
  nn::AdaController copy;
  copy.Restore(state);
  EXPECT_EQ(copy.State(), state);
  for (int i = 0; i < 40; ++i) ada.Observe(-torch::ones({5}));
  EXPECT_EQ(ada.p(), 0.0);  // clamped
}

TEST(GanCamera, TheConditionDoesNotDependOnTheResolution) {
  SplatCamera c = FrontCamera(64, 0.3);
  c.cx = 30.2;
  const torch::Tensor full = CameraCondition(c), quarter = CameraCondition(c.Downscaled(4));
  ASSERT_EQ(full.numel(), 16);
  EXPECT_TRUE(torch::allclose(full, quarter, 0, 1e-6));
}

// CompareExpressions against plain loops over the same numbers: the distance
// to the driving weights, the baseline's, the ordering by spread and the
// Pearson correlation; a constant column correlates 0, an exact copy 1 and
// a mirrored one -1.
TEST(ExpressionAgreement, MatchesAPlainComputation) {
  const int n = 7, e = 4;
  std::vector<double> d(n * e), t(n * e), b = {0.1, 0.0, 0.3, 0.2};
  for (int i = 0; i < n; ++i) {
    d[i * e + 0] = 0.1 * i;                     // spread 0.2
    d[i * e + 1] = 0.5;                         // constant
    d[i * e + 2] = 0.05 * ((i * 3) % 5);        // spread about 0.07
    d[i * e + 3] = 0.02 * i;                    // spread 0.04
    t[i * e + 0] = 0.1 * i;                     // read back exactly
    t[i * e + 1] = 0.4 + 0.01 * i;              // varies where the driver does not
    t[i * e + 2] = 0.3 - 0.05 * ((i * 3) % 5);  // mirrored
    t[i * e + 3] = 0.07;                        // constant
  }
  const auto tensor = [](const std::vector<double>& v, std::vector<int64_t> shape) {
    return torch::tensor(v, torch::kFloat64).reshape(shape);
  };
  const ExpressionAgreement a =
      CompareExpressions(tensor(d, {n, e}), tensor(t, {n, e}), tensor(b, {e}), {"a", "b", "c", "d"}, 3);
  double error = 0, baseline = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < e; ++j) {
      error += std::abs(t[i * e + j] - d[i * e + j]);
      baseline += std::abs(b[size_t(j)] - d[i * e + j]);
    }
  EXPECT_EQ(a.frames, n);
  EXPECT_NEAR(a.error, error / (n * e), 1e-12);
  EXPECT_NEAR(a.baseline_error, baseline / (n * e), 1e-12);
  ASSERT_EQ(a.blendshapes.size(), 3u);
  EXPECT_EQ(a.blendshapes[0].name, "a");
  EXPECT_EQ(a.blendshapes[1].name, "c");
  EXPECT_EQ(a.blendshapes[2].name, "d");
  EXPECT_NEAR(a.blendshapes[0].driving_std, 0.2, 1e-12);
  EXPECT_NEAR(a.blendshapes[0].correlation, 1.0, 1e-12);
  EXPECT_NEAR(a.blendshapes[0].error, 0.0, 1e-12);
  EXPECT_NEAR(a.blendshapes[1].correlation, -1.0, 1e-12);
  EXPECT_NEAR(a.blendshapes[2].correlation, 0.0, 1e-12);  // read back as a constant
  double c_error = 0, c_baseline = 0;
  for (int i = 0; i < n; ++i) {
    c_error += std::abs(t[i * e + 2] - d[i * e + 2]);
    c_baseline += std::abs(b[2] - d[i * e + 2]);
  }
  EXPECT_NEAR(a.blendshapes[1].error, c_error / n, 1e-12);
  EXPECT_NEAR(a.blendshapes[1].baseline_error, c_baseline / n, 1e-12);
  // Nothing to compare: no frames.
  EXPECT_EQ(CompareExpressions(torch::zeros({0, e}), torch::zeros({0, e}), torch::zeros({e}), {}).frames, 0);
}

}  // namespace
}  // namespace headforge
