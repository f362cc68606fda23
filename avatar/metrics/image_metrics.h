// Image losses and quality metrics on [C, H, W] or [B, C, H, W] tensors in [0, 1].
#pragma once

#include <torch/types.h>

namespace headforge {

// Structural similarity with an 11x11 Gaussian window (sigma 1.5) and the
// usual constants (0.01^2, 0.03^2), averaged over pixels and channels;
// differentiable. Windows are zero-padded at the borders.
torch::Tensor Ssim(const torch::Tensor& a, const torch::Tensor& b);
// The per-pixel SSIM map behind it, [B, C, H, W].
torch::Tensor SsimMap(const torch::Tensor& a, const torch::Tensor& b);

// Peak signal-to-noise ratio in dB for a peak of 1.
double Psnr(const torch::Tensor& a, const torch::Tensor& b);

// The gradient magnitude [B, 1, H, W] of an image's grey level (the mean of
// its channels): sqrt(dx^2 + dy^2) with central differences, one-sided at
// the borders; in grey levels per pixel.
torch::Tensor GradientMagnitude(const torch::Tensor& image);
// Sharpness: the mean gradient magnitude over `mask` [1, H, W] (> 0.5) of
// `image` [3, H, W]. The sharpness difference (SD) of a render is its
// sharpness minus the ground truth's over the same mask: negative when the
// render is blurrier.
double Sharpness(const torch::Tensor& image, const torch::Tensor& mask);

}  // namespace headforge
