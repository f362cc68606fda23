#include "avatar/metrics/image_metrics.h"

#include <torch/torch.h>

#include <cmath>

namespace headforge {

torch::Tensor SsimMap(const torch::Tensor& a, const torch::Tensor& b) {
  TORCH_CHECK(a.sizes() == b.sizes(), "Ssim: images differ in size: ", a.sizes(), " vs ", b.sizes());
  const torch::Tensor x = a.dim() == 3 ? a.unsqueeze(0) : a;
  const torch::Tensor y = b.dim() == 3 ? b.unsqueeze(0) : b;
  const int64_t channels = x.size(1);
  constexpr int kSize = 11;
  const torch::Tensor r = torch::arange(kSize, x.options()) - (kSize - 1) / 2.0;
  torch::Tensor g = torch::exp(-(r * r) / (2 * 1.5 * 1.5));
  g = g / g.sum();
  // The window is separable: a row pass and a column pass.
  const torch::Tensor row = g.view({1, 1, 1, kSize}).expand({channels, 1, 1, kSize}).contiguous();
  const torch::Tensor col = g.view({1, 1, kSize, 1}).expand({channels, 1, kSize, 1}).contiguous();
  auto blur = [&](const torch::Tensor& t) {
    const torch::Tensor h = torch::conv2d(t, row, {}, 1, at::IntArrayRef{0, kSize / 2}, 1, channels);
    return torch::conv2d(h, col, {}, 1, at::IntArrayRef{kSize / 2, 0}, 1, channels);
  };
  const torch::Tensor mx = blur(x), my = blur(y);
  const torch::Tensor sxx = blur(x * x) - mx * mx;
  const torch::Tensor syy = blur(y * y) - my * my;
  const torch::Tensor sxy = blur(x * y) - mx * my;
  constexpr double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
  const torch::Tensor map = ((2 * mx * my + c1) * (2 * sxy + c2)) /
                            ((mx * mx + my * my + c1) * (sxx + syy + c2));
  return map;
}

torch::Tensor Ssim(const torch::Tensor& a, const torch::Tensor& b) { return SsimMap(a, b).mean(); }

double Psnr(const torch::Tensor& a, const torch::Tensor& b) {
  const double mse = (a.to(torch::kFloat64) - b.to(torch::kFloat64)).pow(2).mean().item<double>();
  return mse > 0 ? -10.0 * std::log10(mse) : INFINITY;
}

}  // namespace headforge
