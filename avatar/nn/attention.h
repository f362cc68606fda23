// The transformer block of the gaussian-style deformation: each Gaussian's
// feature (a query) attends to condition tokens made from a frame's tracking
// parameters, then passes a gated-MLP feed-forward, both with skip
// connections: F' = CA(LN(F), LN(c)) + F; Z = FFN(LN(F')) + F'.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/modules/normalization.h>
#include <torch/nn/pimpl.h>

namespace headforge::nn {

// Multi-head cross-attention: queries [N, D] attend to tokens [K, D] -> [N, D].
class CrossAttentionImpl : public torch::nn::Module {
 public:
  CrossAttentionImpl(int64_t dim, int64_t heads);
  torch::Tensor forward(const torch::Tensor& queries, const torch::Tensor& tokens);

 private:
  int64_t heads_;
  torch::nn::Linear q_{nullptr}, k_{nullptr}, v_{nullptr}, out_{nullptr};
};
TORCH_MODULE(CrossAttention);

// W2 (GELU(W1 x) * W3 x): the gated-MLP feed-forward (GEGLU), [N, D] -> [N, D].
class GatedFeedForwardImpl : public torch::nn::Module {
 public:
  GatedFeedForwardImpl(int64_t dim, int64_t hidden);
  torch::Tensor forward(const torch::Tensor& x);

 private:
  torch::nn::Linear gate_{nullptr}, value_{nullptr}, out_{nullptr};
};
TORCH_MODULE(GatedFeedForward);

class CrossAttentionBlockImpl : public torch::nn::Module {
 public:
  CrossAttentionBlockImpl(int64_t dim, int64_t heads, int64_t hidden);
  // features [N, D], tokens [K, D] -> [N, D]
  torch::Tensor forward(const torch::Tensor& features, const torch::Tensor& tokens);

 private:
  torch::nn::LayerNorm norm_q_{nullptr}, norm_c_{nullptr}, norm_f_{nullptr};
  CrossAttention attention_{nullptr};
  GatedFeedForward ffn_{nullptr};
};
TORCH_MODULE(CrossAttentionBlock);

}  // namespace headforge::nn
