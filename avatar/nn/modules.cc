// The shared modules of avatar/nn: mlp.h, modulated_conv.h, triplane.h, attention.h.
#include <torch/torch.h>

#include <cmath>

#include "avatar/nn/attention.h"
#include "avatar/nn/functional.h"
#include "avatar/nn/mlp.h"
#include "avatar/nn/modulated_conv.h"
#include "avatar/nn/triplane.h"

namespace headforge::nn {

namespace F = torch::nn::functional;

MlpImpl::MlpImpl(const std::vector<int64_t>& widths, bool zero_last) {
  TORCH_CHECK(widths.size() >= 2, "an MLP needs an input and an output width");
  for (size_t i = 0; i + 1 < widths.size(); ++i)
    layers_.push_back(register_module("layer" + std::to_string(i), torch::nn::Linear(widths[i], widths[i + 1])));
  if (zero_last) {
    torch::NoGradGuard no_grad;
    layers_.back()->weight.zero_();
    layers_.back()->bias.zero_();
  }
}

torch::Tensor MlpImpl::forward(const torch::Tensor& x) {
  torch::Tensor y = x;
  for (size_t i = 0; i < layers_.size(); ++i) {
    y = layers_[i]->forward(y);
    if (i + 1 < layers_.size()) y = LeakyRelu(y);
  }
  return y;
}

MappingNetworkImpl::MappingNetworkImpl(int64_t z_dim, int64_t w_dim, int layers) {
  std::vector<int64_t> widths = {z_dim};
  for (int i = 0; i < layers; ++i) widths.push_back(w_dim);
  mlp_ = register_module("mlp", Mlp(widths));
}

torch::Tensor MappingNetworkImpl::forward(const torch::Tensor& z) {
  return mlp_->forward(z * torch::rsqrt(z.pow(2).mean(-1, true) + 1e-8));
}

ModulatedConv2dImpl::ModulatedConv2dImpl(int64_t in_channels, int64_t out_channels, int64_t kernel, int64_t w_dim,
                                         bool demodulate)
    : kernel_(kernel), demodulate_(demodulate) {
  TORCH_CHECK(kernel % 2 == 1, "the modulated convolution's kernel must be odd");
  weight = register_parameter("weight", torch::randn({out_channels, in_channels, kernel, kernel}) /
                                            std::sqrt(double(in_channels * kernel * kernel)));
  bias = register_parameter("bias", torch::zeros({out_channels}));
  affine_ = register_module("affine", torch::nn::Linear(w_dim, in_channels));
  torch::NoGradGuard no_grad;
  affine_->weight.mul_(0.5);
  affine_->bias.fill_(1.0);  // styles start near one: the plain convolution
}

torch::Tensor ModulatedConv2dImpl::Style(const torch::Tensor& w) { return affine_->forward(w); }

torch::Tensor ModulatedConv2dImpl::forward(const torch::Tensor& x, const torch::Tensor& w) {
  const int64_t batch = x.size(0), in = weight.size(1), out = weight.size(0);
  TORCH_CHECK(x.size(1) == in, "modulated convolution: ", x.size(1), " input channels for ", in);
  const torch::Tensor s = Style(w);                                            // [B, in]
  torch::Tensor wt = weight.unsqueeze(0) * s.view({batch, 1, in, 1, 1});       // [B, out, in, k, k]
  if (demodulate_) wt = wt * torch::rsqrt(wt.pow(2).sum({2, 3, 4}, true) + 1e-8);
  const torch::Tensor y =
      F::conv2d(x.reshape({1, batch * in, x.size(2), x.size(3)}), wt.reshape({batch * out, in, kernel_, kernel_}),
                F::Conv2dFuncOptions().padding(kernel_ / 2).groups(batch));
  return y.view({batch, out, x.size(2), x.size(3)}) + bias.view({1, out, 1, 1});
}

torch::Tensor SampleTriplane(const torch::Tensor& planes, const torch::Tensor& points) {
  const bool batched = planes.dim() == 5;
  TORCH_CHECK((planes.dim() == 4 || batched) && planes.size(batched ? 1 : 0) == 3,
              "triplane: planes must be [3, C, R, R] or [B, 3, C, R, R]");
  TORCH_CHECK(points.dim() == (batched ? 3 : 2) && points.size(-1) == 3 &&
                  (!batched || points.size(0) == planes.size(0)),
              "triplane: points must be [N, 3], or [B, N, 3] with batched planes");
  const int64_t b = batched ? planes.size(0) : 1, n = points.size(-2), c = planes.size(-3), r = planes.size(-1);
  const torch::Tensor p = points.reshape({b, n, 3});
  const torch::Tensor x = p.select(2, 0), y = p.select(2, 1), z = p.select(2, 2);
  // [B, 3, N, 2]: (u, v) on the xy, xz and zy planes, one grid per plane.
  const torch::Tensor grid = torch::stack({torch::stack({x, y}, 2), torch::stack({x, z}, 2), torch::stack({z, y}, 2)}, 1);
  const torch::Tensor sampled = F::grid_sample(planes.reshape({b * 3, c, r, r}),
                                               grid.reshape({b * 3, 1, n, 2}).to(planes.dtype()),
                                               F::GridSampleFuncOptions()
                                                   .mode(torch::kBilinear)
                                                   .padding_mode(torch::kBorder)
                                                   .align_corners(false));  // [B * 3, C, 1, N]
  const torch::Tensor out = sampled.view({b, 3, c, n}).permute({0, 3, 1, 2}).reshape({b, n, 3 * c});
  return batched ? out : out.squeeze(0);
}

TriplaneGeneratorImpl::TriplaneGeneratorImpl(const TriplaneGeneratorOptions& options) : options_(options) {
  TORCH_CHECK(options.resolution >= 8 && (options.resolution & (options.resolution - 1)) == 0,
              "triplane: the resolution must be a power of two of at least 8");
  mapping_ = register_module("mapping", MappingNetwork(options.latent_dim, options.w_dim, options.mapping_layers));
  constant_ = register_parameter("constant", torch::randn({1, options.channels, 4, 4}));
  convs_ = register_module("convs", torch::nn::ModuleList());
  convs_->push_back(ModulatedConv2d(options.channels, options.channels, 3, options.w_dim));
  for (int64_t r = 8; r <= options.resolution; r *= 2) {
    convs_->push_back(ModulatedConv2d(options.channels, options.channels, 3, options.w_dim));
    convs_->push_back(ModulatedConv2d(options.channels, options.channels, 3, options.w_dim));
  }
  to_planes_ = register_module(
      "to_planes", ModulatedConv2d(options.channels, 3 * options.plane_channels, 1, options.w_dim, false));
}

torch::Tensor TriplaneGeneratorImpl::Map(const torch::Tensor& latent) { return mapping_->forward(latent); }

torch::Tensor TriplaneGeneratorImpl::Synthesize(const torch::Tensor& w) {
  const int64_t batch = w.size(0);
  torch::Tensor x = constant_.expand({batch, -1, -1, -1});
  size_t next = 0;
  x = LeakyRelu(convs_[next++]->as<ModulatedConv2d>()->forward(x, w));
  for (int64_t r = 8; r <= options_.resolution; r *= 2) {
    x = ResizeBilinear(x, r, r);
    x = LeakyRelu(convs_[next++]->as<ModulatedConv2d>()->forward(x, w));
    x = LeakyRelu(convs_[next++]->as<ModulatedConv2d>()->forward(x, w));
  }
  const torch::Tensor planes = to_planes_->forward(x, w);
  return planes.view({batch, 3, options_.plane_channels, options_.resolution, options_.resolution});
}

CrossAttentionImpl::CrossAttentionImpl(int64_t dim, int64_t heads) : heads_(heads) {
  TORCH_CHECK(dim % heads == 0, "attention: the width must divide into the heads");
  q_ = register_module("q", torch::nn::Linear(dim, dim));
  k_ = register_module("k", torch::nn::Linear(dim, dim));
  v_ = register_module("v", torch::nn::Linear(dim, dim));
  out_ = register_module("out", torch::nn::Linear(dim, dim));
}

torch::Tensor CrossAttentionImpl::forward(const torch::Tensor& queries, const torch::Tensor& tokens) {
  const int64_t n = queries.size(0), k = tokens.size(0), dim = queries.size(1), d = dim / heads_;
  const torch::Tensor q = q_->forward(queries).view({n, heads_, d}).transpose(0, 1);  // [H, N, d]
  const torch::Tensor kk = k_->forward(tokens).view({k, heads_, d}).transpose(0, 1);  // [H, K, d]
  const torch::Tensor v = v_->forward(tokens).view({k, heads_, d}).transpose(0, 1);   // [H, K, d]
  const torch::Tensor weights = torch::softmax(torch::matmul(q, kk.transpose(1, 2)) / std::sqrt(double(d)), -1);
  return out_->forward(torch::matmul(weights, v).transpose(0, 1).reshape({n, dim}));
}

GatedFeedForwardImpl::GatedFeedForwardImpl(int64_t dim, int64_t hidden) {
  gate_ = register_module("gate", torch::nn::Linear(dim, hidden));
  value_ = register_module("value", torch::nn::Linear(dim, hidden));
  out_ = register_module("out", torch::nn::Linear(hidden, dim));
}

torch::Tensor GatedFeedForwardImpl::forward(const torch::Tensor& x) {
  return out_->forward(F::gelu(gate_->forward(x)) * value_->forward(x));
}

CrossAttentionBlockImpl::CrossAttentionBlockImpl(int64_t dim, int64_t heads, int64_t hidden) {
  norm_q_ = register_module("norm_q", torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim})));
  norm_c_ = register_module("norm_c", torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim})));
  norm_f_ = register_module("norm_f", torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim})));
  attention_ = register_module("attention", CrossAttention(dim, heads));
  ffn_ = register_module("ffn", GatedFeedForward(dim, hidden));
}

torch::Tensor CrossAttentionBlockImpl::forward(const torch::Tensor& features, const torch::Tensor& tokens) {
  const torch::Tensor attended = features + attention_->forward(norm_q_->forward(features), norm_c_->forward(tokens));
  return attended + ffn_->forward(norm_f_->forward(attended));
}

}  // namespace headforge::nn
