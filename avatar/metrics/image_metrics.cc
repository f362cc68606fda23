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

torch::Tensor GradientMagnitude(const torch::Tensor& image) {
  const torch::Tensor x = (image.dim() == 3 ? image.unsqueeze(0) : image).mean(1, true);
  const int64_t h = x.size(2), w = x.size(3);
  TORCH_CHECK(h >= 2 && w >= 2, "GradientMagnitude: the image must be at least 2x2");
  // Central differences inside, one-sided at the first and last column / row.
  torch::Tensor dx = torch::empty_like(x), dy = torch::empty_like(x);
  dx.slice(3, 1, w - 1) = (x.slice(3, 2, w) - x.slice(3, 0, w - 2)) / 2;
  dx.slice(3, 0, 1) = x.slice(3, 1, 2) - x.slice(3, 0, 1);
  dx.slice(3, w - 1, w) = x.slice(3, w - 1, w) - x.slice(3, w - 2, w - 1);
  dy.slice(2, 1, h - 1) = (x.slice(2, 2, h) - x.slice(2, 0, h - 2)) / 2;
  dy.slice(2, 0, 1) = x.slice(2, 1, 2) - x.slice(2, 0, 1);
  dy.slice(2, h - 1, h) = x.slice(2, h - 1, h) - x.slice(2, h - 2, h - 1);
  return (dx * dx + dy * dy).sqrt();
}

double Sharpness(const torch::Tensor& image, const torch::Tensor& mask) {
  const torch::Tensor g = GradientMagnitude(image.to(torch::kFloat64))[0];  // [1, H, W]
  const torch::Tensor m = (mask.to(torch::kFloat64) > 0.5).to(torch::kFloat64);
  const double count = m.sum().item<double>();
  return count > 0 ? (g * m).sum().item<double>() / count : 0.0;
}

}  // namespace headforge
