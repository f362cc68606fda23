#include "avatar/train/adam.h"

#include <torch/torch.h>

#include <cmath>

namespace headforge {

void Adam::Add(torch::Tensor* param, double lr, bool rows) {
  slots_.push_back({param, lr, rows, torch::zeros_like(*param), torch::zeros_like(*param)});
}

void Adam::Step() {
  torch::NoGradGuard no_grad;
  ++t_;
  const double c1 = 1 - std::pow(beta1_, t_), c2 = 1 - std::pow(beta2_, t_);
  for (Slot& s : slots_) {
    const torch::Tensor& g = s.param->grad();
    if (!g.defined()) continue;
    s.m.mul_(beta1_).add_(g, 1 - beta1_);
    s.v.mul_(beta2_).addcmul_(g, g, 1 - beta2_);
    const torch::Tensor denom = (s.v / c2).sqrt_().add_(kEps);
    s.param->addcdiv_(s.m, denom, -s.lr / c1);
  }
}

void Adam::ZeroGrad() {
  for (Slot& s : slots_)
    if (s.param->grad().defined()) s.param->mutable_grad().zero_();
}

void Adam::Edit(const torch::Tensor& keep, const std::vector<torch::Tensor>& append) {
  torch::NoGradGuard no_grad;
  size_t next = 0;
  for (Slot& s : slots_) {
    if (!s.rows) continue;
    const torch::Tensor& extra = append.at(next++);
    auto gather = [&](const torch::Tensor& t, const torch::Tensor& added) {
      const torch::Tensor kept = keep.defined() ? t.index_select(0, keep) : t;
      return added.defined() && added.size(0) > 0 ? torch::cat({kept, added}) : kept;
    };
    *s.param = gather(s.param->detach(), extra).requires_grad_(true);
    const torch::Tensor zeros = extra.defined() ? torch::zeros_like(extra) : torch::Tensor();
    s.m = gather(s.m, zeros);
    s.v = gather(s.v, zeros);
  }
}

void Adam::ResetMoments(size_t index) {
  slots_[index].m.zero_();
  slots_[index].v.zero_();
}

void Adam::Save(const std::string& prefix, Checkpoint* c) const {
  c->Put(prefix + "t", t_);
  for (size_t i = 0; i < slots_.size(); ++i) {
    c->Put(prefix + "m." + std::to_string(i), slots_[i].m);
    c->Put(prefix + "v." + std::to_string(i), slots_[i].v);
  }
}

bool Adam::Load(const std::string& prefix, const Checkpoint& c) {
  if (!c.Get(prefix + "t", &t_)) return false;
  for (size_t i = 0; i < slots_.size(); ++i) {
    Slot& s = slots_[i];
    if (!c.Get(prefix + "m." + std::to_string(i), &s.m) || !c.Get(prefix + "v." + std::to_string(i), &s.v))
      return false;
    if (!s.m.sizes().equals(s.param->sizes())) return false;
    s.m = s.m.to(s.param->device());
    s.v = s.v.to(s.param->device());
  }
  return true;
}

}  // namespace headforge
