// Hard cases: every one stays finite and agrees with the reference.
#include "avatar/splat/splat_test_util.h"

namespace headforge::splat_test {
namespace {

// Forward and gradients finite and equal to the reference (double).
void ExpectMatchesReference(const Scene& s, double tolerance = 1e-8) {
  const Rendered k = RenderKernel(s, true);
  const Rendered r = RenderReference(s, true);
  EXPECT_TRUE(AllFinite(k.image) && AllFinite(k.alpha) && AllFinite(k.depth));
  EXPECT_LE(MaxAbsDiff(k.image, r.image), tolerance);
  EXPECT_LE(MaxAbsDiff(k.alpha, r.alpha), tolerance);
  EXPECT_LE(MaxAbsDiff(k.depth, r.depth), tolerance * 10);
  const Loss loss(s.features.size(1), s.camera.height, s.camera.width, 99);
  const auto gk = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x, true); });
  const auto gr = Gradients(s, loss, [](const Scene& x) { return RenderReference(x, true); });
  for (size_t i = 0; i < gk.size(); ++i) {
    SCOPED_TRACE(kInputNames[i]);
    EXPECT_TRUE(AllFinite(gk[i]));
    EXPECT_LE(MaxAbsDiff(gk[i], gr[i]), tolerance * std::max(1.0, MaxAbs(gr[i])));
  }
}

Scene WithDepths(Scene s, const std::vector<double>& z) {
  torch::NoGradGuard no_grad;
  for (size_t i = 0; i < z.size(); ++i) {
    s.means[int64_t(i)][0] = 0.05 * double(i);
    s.means[int64_t(i)][2] = z[i];
  }
  return s;
}

TEST(SplatHardCases, BehindAndOnTheCameraPlaneAreCulled) {
  // In the camera frame (the camera is rotated and shifted: set z through it).
  Scene s = RandomScene(6, 3, 10);
  s.camera.cam_from_world = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  s = WithDepths(s, {-1.0, 0.0, 1e-9, 0.005, 2.0, -1e-12});
  const auto p = ProjectKernel(s);
  const auto radii = p.radii.accessor<int32_t, 1>();
  for (int i : {0, 1, 2, 3, 5}) EXPECT_EQ(radii[i], 0) << i;
  EXPECT_GT(radii[4], 0);
  EXPECT_TRUE(AllFinite(p.means2d) && AllFinite(p.conics));
  ExpectMatchesReference(s);
  const Loss loss(3, 36, 40, 1);
  const auto g = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x); });
  for (int i : {0, 1, 2, 3, 5}) {
    EXPECT_EQ(MaxAbs(g[0][i]), 0.0) << "culled Gaussian " << i << " got a mean gradient";
  }
}

TEST(SplatHardCases, TinyAndHugeScales) {
  Scene s = RandomScene(40, 3, 11);
  {
    torch::NoGradGuard no_grad;
    s.log_scales.slice(0, 0, 10).fill_(std::log(1e-8));
    s.log_scales.slice(0, 10, 12).fill_(std::log(1e3));
  }
  const auto p = ProjectKernel(s);
  // Tiny Gaussians still project to the low-pass footprint: 3 sigma of
  // sqrt(0.3 + sqrt(0.1)) pixels, rounded up.
  const auto r = p.radii.accessor<int32_t, 1>();
  for (int i = 0; i < 10; ++i) {
    if (r[i] > 0) {
      EXPECT_EQ(r[i], 3) << i;
    }
  }
  ExpectMatchesReference(s, 1e-7);
}

TEST(SplatHardCases, NearlySingularCovariances) {
  Scene s = RandomScene(40, 3, 12);
  {
    torch::NoGradGuard no_grad;
    // Needles: one axis 1e-7 of the others, at random orientations; some of
    // them seen edge-on, others along the thin axis.
    s.log_scales.select(1, 0).fill_(std::log(1e-8));
    s.log_scales.select(1, 1).fill_(std::log(0.1));
    s.log_scales.select(1, 2).fill_(std::log(1e-8));
  }
  ExpectMatchesReference(s, 1e-7);
  // And with no low-pass filter, where the 2D covariance itself is singular:
  // culled, not NaN.
  SplatOptions options;
  options.eps2d = 0;
  const auto p = ProjectKernel(s, options);
  EXPECT_TRUE(AllFinite(p.conics) && AllFinite(p.means2d));
}

TEST(SplatHardCases, OpacityZeroAndOne) {
  Scene s = RandomScene(30, 3, 13);
  {
    torch::NoGradGuard no_grad;
    s.opacities.slice(0, 0, 15).fill_(0.0);
    s.opacities.slice(0, 15, 30).fill_(1.0);
  }
  ExpectMatchesReference(s);
  // Alpha never reaches 1, so a lone opaque Gaussian still shows 0.1% of the background.
  Scene one = RandomScene(1, 3, 14);
  {
    torch::NoGradGuard no_grad;
    one.camera.cam_from_world = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    one.opacities.fill_(1.0);
    one.means.copy_(torch::tensor({{0.0, 0.0, 2.0}}, torch::kFloat64));
    one.camera.cx = 20;
    one.camera.cy = 18;
  }
  const Rendered k = RenderKernel(one);
  EXPECT_NEAR(k.alpha[18][20].item<double>(), 0.999, 1e-12);
  for (int c = 0; c < 3; ++c) {
    const double expect = 0.999 * one.features[0][c].item<double>() +
                          0.001 * one.background[c].item<double>();
    EXPECT_NEAR(k.image[c][18][20].item<double>(), expect, 1e-12);
  }
}

TEST(SplatHardCases, NoGaussiansAndOne) {
  Scene none = RandomScene(0, 3, 15);
  const Rendered k = RenderKernel(none);
  for (int c = 0; c < 3; ++c) {
    EXPECT_LE(MaxAbsDiff(k.image[c], none.background[c].expand({36, 40})), 0.0);
  }
  EXPECT_EQ(MaxAbs(k.alpha), 0.0);
  const Loss loss(3, 36, 40, 2);
  const auto g = Gradients(none, loss, [](const Scene& x) { return RenderKernel(x); });
  // d loss / d background_c = sum of the image weights of channel c.
  EXPECT_LE(MaxAbsDiff(g[5], loss.w_image.sum({1, 2})), 1e-10);
  ExpectMatchesReference(RandomScene(1, 3, 16));
}

TEST(SplatHardCases, OffScreenGaussiansDoNothing) {
  Scene s = RandomScene(20, 3, 17);
  {
    torch::NoGradGuard no_grad;
    s.means.select(1, 0).add_(100.0);  // far to the right of the view
  }
  const auto p = ProjectKernel(s);
  EXPECT_EQ(p.radii.sum().item<int64_t>(), 0);
  const Rendered k = RenderKernel(s);
  EXPECT_EQ(MaxAbs(k.alpha), 0.0);
  ExpectMatchesReference(s);
}

TEST(SplatHardCases, HundredsOnOnePixelUnderflowTransmittance) {
  // 600 nearly opaque Gaussians stacked on the same pixel: transmittance would
  // underflow; the early stop keeps it above 1e-4 and the backward's division
  // finite.
  Scene s = RandomScene(600, 32, 18);
  {
    torch::NoGradGuard no_grad;
    s.camera.cam_from_world = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    const auto z = torch::linspace(2.0, 3.0, 600, torch::kFloat64);
    s.means.copy_(torch::stack({0.01 * z, -0.02 * z, z}, 1));
    s.opacities.uniform_(0.6, 1.0);
  }
  const Rendered k = RenderKernel(s);
  // Coverage saturates just below 1 - 1e-4, the last transmittance kept.
  EXPECT_GT(k.alpha.max().item<double>(), 0.9998);
  EXPECT_LE(k.alpha.max().item<double>(), 1 - 1e-4 + 1e-12);
  EXPECT_GE(k.alpha.min().item<double>(), 0.0);
  ExpectMatchesReference(s, 1e-7);
  // The float kernels too.
  const Scene f = s.To(torch::kFloat32);
  const Loss loss(32, 36, 40, 3);
  const auto g = Gradients(f, loss, [](const Scene& x) { return RenderKernel(x); });
  for (const auto& t : g) EXPECT_TRUE(AllFinite(t));
}

TEST(SplatHardCases, ZeroQuaternionIsCulledNotNaN) {
  Scene s = RandomScene(5, 3, 19);
  {
    torch::NoGradGuard no_grad;
    s.quats[2].zero_();
  }
  const auto p = ProjectKernel(s);
  EXPECT_EQ(p.radii[2].item<int32_t>(), 0);
  const Loss loss(3, 36, 40, 4);
  const auto g = Gradients(s, loss, [](const Scene& x) { return RenderKernel(x); });
  for (const auto& t : g) EXPECT_TRUE(AllFinite(t));
}

}  // namespace
}  // namespace headforge::splat_test
