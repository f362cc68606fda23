#include "avatar/gan_avatar/expression_mapping.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>

namespace headforge {

ExpressionMappingImpl::ExpressionMappingImpl(int64_t expressions, int64_t w_dim, int64_t hidden) {
  mlp_ = register_module("mlp", nn::Mlp(std::vector<int64_t>{expressions, hidden, hidden, w_dim}));
}

ExpressionAgreement CompareExpressions(const torch::Tensor& driving, const torch::Tensor& tracked,
                                       const torch::Tensor& baseline, const std::vector<std::string>& names, int top) {
  const torch::Tensor d = driving.to(torch::kFloat64), t = tracked.to(torch::kFloat64),
                      b = baseline.to(torch::kFloat64).reshape({1, -1}).expand_as(d);
  ExpressionAgreement a;
  a.frames = int(d.size(0));
  if (a.frames == 0) return a;
  a.error = (t - d).abs().mean().item<double>();
  a.baseline_error = (b - d).abs().mean().item<double>();
  const torch::Tensor spread = d.std(0, /*unbiased=*/false);
  const torch::Tensor order = spread.argsort(0, /*descending=*/true);
  for (int64_t k = 0; k < std::min<int64_t>(top, d.size(1)); ++k) {
    const int64_t j = order[k].item<int64_t>();
    ExpressionAgreement::Blendshape s;
    s.name = size_t(j) < names.size() ? names[size_t(j)] : std::to_string(j);
    s.column = j;
    s.driving_std = spread[j].item<double>();
    const torch::Tensor dj = d.select(1, j), tj = t.select(1, j);
    s.error = (tj - dj).abs().mean().item<double>();
    s.baseline_error = (b.select(1, j) - dj).abs().mean().item<double>();
    const torch::Tensor dc = dj - dj.mean(), tc = tj - tj.mean();
    const double norm = std::sqrt(dc.pow(2).sum().item<double>() * tc.pow(2).sum().item<double>());
    s.correlation = norm > 1e-12 ? (dc * tc).sum().item<double>() / norm : 0.0;
    a.blendshapes.push_back(s);
  }
  return a;
}

}  // namespace headforge
