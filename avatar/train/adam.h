// Adam over a trainer's parameters: the Gaussians' rows (which densification
// gathers and extends, moments and all) and networks' weights in one
// optimiser, each parameter with its own learning rate; its state goes into a
// Checkpoint so that a resumed run steps exactly as an uninterrupted one.
#pragma once

#include <torch/types.h>

#include <string>
#include <vector>

#include "avatar/train/checkpoint.h"

namespace headforge {

class Adam {
 public:
  // The moments' decay rates (a GAN's networks take beta1 = 0, StyleGAN2's 0 and 0.99).
  explicit Adam(double beta1 = 0.9, double beta2 = 0.999) : beta1_(beta1), beta2_(beta2) {}
  // `param` must outlive the optimiser (Gaussian parameters are replaced by
  // densification: the optimiser follows the pointer). `rows`: a per-Gaussian
  // parameter that Edit() gathers and extends.
  void Add(torch::Tensor* param, double lr, bool rows);
  size_t size() const { return slots_.size(); }
  void SetLr(size_t index, double lr) { slots_[index].lr = lr; }
  double lr(size_t index) const { return slots_[index].lr; }
  // The parameters, in the order they were added.
  std::vector<torch::Tensor*> Parameters() const {
    std::vector<torch::Tensor*> out;
    for (const Slot& s : slots_) out.push_back(s.param);
    return out;
  }

  void Step();
  void ZeroGrad();

  // Every row parameter becomes its rows `keep` (all when undefined), then
  // `append`'s rows (one tensor per row parameter, in the order they were
  // added; new rows get zero moments).
  void Edit(const torch::Tensor& keep, const std::vector<torch::Tensor>& append);
  void ResetMoments(size_t index);

  void Save(const std::string& prefix, Checkpoint* checkpoint) const;
  // After the parameters themselves were restored (moments follow their devices).
  bool Load(const std::string& prefix, const Checkpoint& checkpoint);

 private:
  struct Slot {
    torch::Tensor* param;
    double lr;
    bool rows;
    torch::Tensor m, v;
  };
  static constexpr double kEps = 1e-15;
  double beta1_, beta2_;
  std::vector<Slot> slots_;
  int64_t t_ = 0;
};

}  // namespace headforge
