// The activation and the resampling the networks of avatar/nn and the
// models share.
#pragma once

#include <torch/nn/functional/activation.h>
#include <torch/nn/functional/upsampling.h>

#include <vector>

namespace headforge::nn {

// StyleGAN's activation: LeakyReLU with slope 0.2.
inline torch::Tensor LeakyRelu(const torch::Tensor& x) {
  return torch::nn::functional::leaky_relu(x, torch::nn::functional::LeakyReLUFuncOptions().negative_slope(0.2));
}

// x [B, C, h, w] -> [B, C, height, width], bilinear with pixel centres aligned
// (align_corners = false).
inline torch::Tensor ResizeBilinear(const torch::Tensor& x, int64_t height, int64_t width) {
  return torch::nn::functional::interpolate(x, torch::nn::functional::InterpolateFuncOptions()
                                                   .size(std::vector<int64_t>{height, width})
                                                   .mode(torch::kBilinear)
                                                   .align_corners(false));
}

}  // namespace headforge::nn
