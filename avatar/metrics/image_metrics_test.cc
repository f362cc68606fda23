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

}  // namespace
}  // namespace headforge
