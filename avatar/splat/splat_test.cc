// The rasterizer against its plain-tensor reference and finite differences.
#include "avatar/splat/splat_test_util.h"

namespace headforge::splat_test {
namespace {

class SplatChannels : public ::testing::TestWithParam<int> {};

TEST_P(SplatChannels, ProjectionMatchesReference) {
  const Scene s = RandomScene(80, GetParam(), 1);
  const auto k = ProjectKernel(s);
  const auto r = splat_reference::Project(s.means, s.quats, s.log_scales, s.camera);
  EXPECT_TRUE(torch::equal(k.radii, r.radii));
  EXPECT_GT((k.radii > 0).sum().item<int64_t>(), 40);
  EXPECT_LE(MaxAbsDiff(k.means2d, r.means2d), 1e-10);
  EXPECT_LE(MaxAbsDiff(k.conics, r.conics), 1e-10);
  EXPECT_LE(MaxAbsDiff(k.depths, r.depths), 1e-12);
}

TEST_P(SplatChannels, ForwardMatchesReferenceInDouble) {
  const Scene s = RandomScene(120, GetParam(), 2);
  const Rendered k = RenderKernel(s, true);
  const Rendered r = RenderReference(s, true);
  ASSERT_EQ(k.image.sizes(), r.image.sizes());
  EXPECT_EQ(k.image.size(0), GetParam());
  EXPECT_LE(MaxAbsDiff(k.image, r.image), 1e-9);
  EXPECT_LE(MaxAbsDiff(k.alpha, r.alpha), 1e-9);
  EXPECT_LE(MaxAbsDiff(k.depth, r.depth), 1e-8);
  // The scene is not trivial: a fifth of the pixels are more than half covered.
  EXPECT_GT((k.alpha > 0.5).to(torch::kFloat64).mean().item<double>(), 0.2);
}

TEST_P(SplatChannels, GradientsMatchReferenceAutograd) {
  const Scene s = RandomScene(120, GetParam(), 3);
  const Loss loss(GetParam(), s.camera.height, s.camera.width, 30);
  const auto k = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x, true); });
  const auto r = Gradients(s, loss, [](const Scene& x) { return RenderReference(x, true); });
  for (size_t i = 0; i < k.size(); ++i) {
    SCOPED_TRACE(kInputNames[i]);
    ASSERT_TRUE(k[i].defined() && r[i].defined());
    EXPECT_GT(MaxAbs(r[i]), 1e-3);  // the loss does depend on this input
    EXPECT_LE(MaxAbsDiff(k[i], r[i]), 1e-8 * std::max(1.0, MaxAbs(r[i])));
  }
}

// Directional central differences: for random unit directions d per input,
// (L(x + h d) - L(x - h d)) / 2h against <grad L, d>.
TEST_P(SplatChannels, GradientsMatchFiniteDifferences) {
  const Scene s = RandomScene(60, GetParam(), 4);
  const Loss loss(GetParam(), s.camera.height, s.camera.width, 40);
  const auto grads = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x, true); });
  auto gen = at::detail::createCPUGenerator(41);
  const double h = 1e-6;
  for (int i = 0; i < 6; ++i) {
    SCOPED_TRACE(kInputNames[i]);
    for (int trial = 0; trial < 3; ++trial) {
      const torch::Tensor input = s.Inputs()[i];
      torch::Tensor d = torch::randn(input.sizes(), gen, input.options().requires_grad(false));
      d = d / d.norm();
      auto shifted = [&](double step) {
        torch::NoGradGuard no_grad;
        Scene x = s;
        std::vector<torch::Tensor*> fields = {&x.means,     &x.quats,    &x.log_scales,
                                              &x.opacities, &x.features, &x.background};
        *fields[i] = input.detach() + step * d;
        return loss(RenderKernel(x, true)).item<double>();
      };
      const double numeric = (shifted(h) - shifted(-h)) / (2 * h);
      const double analytic = (grads[i] * d).sum().item<double>();
      EXPECT_NEAR(analytic, numeric, 1e-5 * std::max(1.0, std::abs(numeric)))
          << "trial " << trial;
    }
  }
}

// The float kernels (fast exponential, vectorised loops) against the double
// reference.
TEST_P(SplatChannels, FloatMatchesDoubleReference) {
  const Scene s = RandomScene(120, GetParam(), 5);
  const Scene f = s.To(torch::kFloat32);
  const Loss loss(GetParam(), s.camera.height, s.camera.width, 50);
  const Rendered k = RenderKernel(f);
  const Rendered r = RenderReference(s);
  EXPECT_EQ(k.image.scalar_type(), torch::kFloat32);
  EXPECT_LE(MaxAbsDiff(k.image, r.image), 1e-4);
  EXPECT_LE(MaxAbsDiff(k.alpha, r.alpha), 1e-4);
  const auto gk = Gradients(f, loss, [](const Scene& x) { return RenderKernel(x); });
  const auto gr = Gradients(s, loss, [](const Scene& x) { return RenderReference(x); });
  for (size_t i = 0; i < gk.size(); ++i) {
    SCOPED_TRACE(kInputNames[i]);
    EXPECT_LE(MaxAbsDiff(gk[i], gr[i]), 2e-3 * std::max(1.0, MaxAbs(gr[i])));
  }
}

INSTANTIATE_TEST_SUITE_P(Channels, SplatChannels, ::testing::Values(3, 32));

TEST(SplatIntersect, EveryGaussianListedOnItsTilesNearToFar) {
  const Scene s = RandomScene(200, 3, 6, 70, 50);
  const auto p = ProjectKernel(s);
  const auto t = IntersectKernel(p, 70, 50);
  ASSERT_EQ(t.tiles_x, 5);
  ASSERT_EQ(t.tiles_y, 4);
  const auto offsets = t.tile_offsets.accessor<int32_t, 1>();
  const auto ids = t.gaussian_ids.accessor<int32_t, 1>();
  const auto m = p.means2d.accessor<double, 2>();
  const auto r = p.radii.accessor<int32_t, 1>();
  const auto d = p.depths.accessor<double, 1>();
  int64_t expected_total = 0;
  for (int64_t g = 0; g < 200; ++g) {
    if (r[g] == 0) continue;
    const int x0 = std::max(0, int(std::floor((m[g][0] - r[g]) / 16)));
    const int x1 = std::min(4, int(std::floor((m[g][0] + r[g]) / 16)));
    const int y0 = std::max(0, int(std::floor((m[g][1] - r[g]) / 16)));
    const int y1 = std::min(3, int(std::floor((m[g][1] + r[g]) / 16)));
    for (int ty = 0; ty < 4; ++ty) {
      for (int tx = 0; tx < 5; ++tx) {
        const int tile = ty * 5 + tx;
        int found = 0;
        for (int32_t k = offsets[tile]; k < offsets[tile + 1]; ++k) found += ids[k] == g;
        const bool inside = tx >= x0 && tx <= x1 && ty >= y0 && ty <= y1;
        EXPECT_EQ(found, inside ? 1 : 0) << "Gaussian " << g << " tile " << tile;
        expected_total += inside;
      }
    }
  }
  EXPECT_EQ(t.gaussian_ids.numel(), expected_total);
  for (int tile = 0; tile < 20; ++tile) {
    for (int32_t k = offsets[tile] + 1; k < offsets[tile + 1]; ++k) {
      EXPECT_LE(d[ids[k - 1]], d[ids[k]]);
    }
  }
}

TEST(SplatDeterminism, SameBitsEveryRun) {
  const Scene s = RandomScene(300, 32, 7, 64, 48).To(torch::kFloat32);
  const Loss loss(32, 48, 64, 70);
  const auto a = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x); });
  const auto b = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x); });
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(a[i], b[i])) << kInputNames[i];
}

TEST(SplatOps, BadInputsGiveClearErrors) {
  const Scene s = RandomScene(4, 3, 8);
  EXPECT_THROW(ProjectGaussians(s.means.narrow(1, 0, 2), s.quats, s.log_scales, s.camera),
               c10::Error);
  EXPECT_THROW(ProjectGaussians(s.means, s.quats.to(torch::kFloat32), s.log_scales, s.camera),
               c10::Error);
  SplatOptions bad;
  bad.near_plane = -1;
  EXPECT_THROW(ProjectGaussians(s.means, s.quats, s.log_scales, s.camera, bad), c10::Error);
  const auto p = ProjectKernel(s);
  const auto t = IntersectTiles(p.means2d, p.radii, p.depths, 40, 36);
  EXPECT_THROW(RasterizeGaussians(p.means2d, p.conics, s.features, s.opacities, s.background, t,
                                  80, 36),
               c10::Error);
  try {
    RasterizeGaussians(p.means2d, p.conics, s.features, s.opacities, s.background.narrow(0, 0, 2),
                       t, 40, 36);
    ADD_FAILURE() << "a wrong background size was accepted";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("background must be [C]"), std::string::npos);
  }
}

}  // namespace
}  // namespace headforge::splat_test
