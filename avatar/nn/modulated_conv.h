// StyleGAN2's modulated convolution (Karras et al. 2020, "Analyzing and
// Improving the Image Quality of StyleGAN", eq. 1-3): each sample's style
// scales the weight's input channels, and (with demodulation) every output
// channel's weights are renormalised to unit norm, in place of instance
// normalisation. Done as one grouped convolution over the batch.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/pimpl.h>

namespace headforge::nn {

class ModulatedConv2dImpl : public torch::nn::Module {
 public:
  ModulatedConv2dImpl(int64_t in_channels, int64_t out_channels, int64_t kernel, int64_t w_dim, bool demodulate = true);
  // x [B, in, H, W], w [B, w_dim] -> [B, out, H, W] (same padding).
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& w);
  // The per-sample style s [B, in] the affine layer makes of w.
  torch::Tensor Style(const torch::Tensor& w);

  torch::Tensor weight;  // [out, in, k, k]
  torch::Tensor bias;    // [out]

 private:
  torch::nn::Linear affine_{nullptr};
  int64_t kernel_;
  bool demodulate_;
};
TORCH_MODULE(ModulatedConv2d);

}  // namespace headforge::nn
