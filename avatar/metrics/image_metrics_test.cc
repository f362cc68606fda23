#include "avatar/metrics/image_metrics.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

namespace headforge {
namespace {

TEST(ImageMetrics, PsnrOfAKnownError) {
  const auto a = torch::zeros({3, 8, 8});
  EXPECT_NEAR(Psnr(a, a + 0.1), 20.0, 1e-5);  // MSE 0.01
  EXPECT_TRUE(std::isinf(Psnr(a, a)));
}

TEST(ImageMetrics, SsimIsOneForEqualImagesAndFallsWithNoise) {
  auto gen = at::detail::createCPUGenerator(3);
  const auto a = torch::rand({3, 32, 40}, gen);
  EXPECT_NEAR(Ssim(a, a).item<double>(), 1.0, 1e-6);
  const double mild = Ssim(a, (a + 0.05 * torch::randn({3, 32, 40}, gen)).clamp(0, 1)).item<double>();
  const double strong = Ssim(a, (a + 0.3 * torch::randn({3, 32, 40}, gen)).clamp(0, 1)).item<double>();
  EXPECT_LT(mild, 0.99);
  EXPECT_LT(strong, mild);
}

// The separable window equals the dense 11x11 Gaussian window of the
// definition.
TEST(ImageMetrics, SsimMatchesADirectEvaluation) {
  auto gen = at::detail::createCPUGenerator(4);
  const auto a = torch::rand({1, 11, 11}, gen, torch::kFloat64);
  const auto b = torch::rand({1, 11, 11}, gen, torch::kFloat64);
  const auto r = torch::arange(11, torch::kFloat64) - 5;
  auto g = torch::exp(-(r * r) / (2 * 1.5 * 1.5));
  g = g / g.sum();
  const auto w = torch::outer(g, g);
  const double mx = (w * a[0]).sum().item<double>(), my = (w * b[0]).sum().item<double>();
  const double sxx = (w * a[0] * a[0]).sum().item<double>() - mx * mx;
  const double syy = (w * b[0] * b[0]).sum().item<double>() - my * my;
  const double sxy = (w * a[0] * b[0]).sum().item<double>() - mx * my;
  const double c1 = 1e-4, c2 = 9e-4;
  const double expect = (2 * mx * my + c1) * (2 * sxy + c2) / ((mx * mx + my * my + c1) * (sxx + syy + c2));
  // At the centre of an 11x11 image the window lies wholly inside it.
  EXPECT_NEAR(SsimMap(a, b)[0][0][5][5].item<double>(), expect, 1e-12);
}

// A ramp rising s per pixel along x and t along y has gradient magnitude
// sqrt(s^2 + t^2) everywhere, borders included (one-sided differences of a
// linear function are exact); a constant image has none.
TEST(ImageMetrics, GradientMagnitudeOfARampAndAConstant) {
  const double s = 0.01, t = 0.005;
  const torch::Tensor x = torch::arange(20, torch::kFloat64).view({1, 20}).expand({16, 20});
  const torch::Tensor y = torch::arange(16, torch::kFloat64).view({16, 1}).expand({16, 20});
  const torch::Tensor ramp = (s * x + t * y).unsqueeze(0).expand({3, 16, 20});
  const torch::Tensor g = GradientMagnitude(ramp);
  EXPECT_EQ(g.sizes(), (std::vector<int64_t>{1, 1, 16, 20}));
  EXPECT_NEAR(g.min().item<double>(), std::hypot(s, t), 1e-12);
  EXPECT_NEAR(g.max().item<double>(), std::hypot(s, t), 1e-12);
  EXPECT_EQ(GradientMagnitude(torch::full({3, 8, 8}, 0.3, torch::kFloat64)).abs().max().item<double>(), 0.0);
}

// Blurring lowers the sharpness; the mask picks where it is measured.
TEST(ImageMetrics, SharpnessFallsWithBlurAndFollowsTheMask) {
  torch::manual_seed(3);
  const torch::Tensor image = torch::rand({3, 32, 32}, torch::kFloat64);
  const torch::Tensor kernel = torch::full({3, 1, 3, 3}, 1.0 / 9, torch::kFloat64);
  const torch::Tensor blurred = torch::conv2d(image.unsqueeze(0), kernel, {}, 1, 1, 1, 3)[0];
  torch::Tensor mask = torch::zeros({1, 32, 32}, torch::kFloat64);
  mask.slice(1, 4, 28).slice(2, 4, 28) = 1;
  const double sharp = Sharpness(image, mask), soft = Sharpness(blurred, mask);
  EXPECT_GT(sharp, 0.0);
  EXPECT_LT(soft, 0.6 * sharp);
  // Half of the image flat: a mask over that half measures nothing.
  torch::Tensor half = image.clone();
  half.slice(2, 0, 16) = 0.5;
  torch::Tensor left = torch::zeros({1, 32, 32}, torch::kFloat64);
  left.slice(1, 2, 30).slice(2, 2, 14) = 1;
  EXPECT_NEAR(Sharpness(half, left), 0.0, 1e-12);
  EXPECT_EQ(Sharpness(image, torch::zeros({1, 32, 32})), 0.0);
}

}  // namespace
}  // namespace headforge
