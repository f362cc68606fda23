// How a Gaussian scene grows and shrinks during fitting, as a strategy object
// the trainer calls after every backward pass (the adaptive density control
// of 3D Gaussian Splatting: clone small Gaussians and split large ones where
// the screen-space gradient stays high, prune nearly transparent ones, and
// reset opacities now and then).
#pragma once

#include <torch/types.h>

#include <memory>
#include <string>
#include <vector>

#include "avatar/train/checkpoint.h"
#include "avatar/train/splat_fit_options.h"

namespace headforge {

// The fitted parameters; every tensor a leaf with requires_grad.
struct GaussianParams {
  torch::Tensor means;           // [N, 3] world, metres
  torch::Tensor quats;           // [N, 4] (w, x, y, z)
  torch::Tensor log_scales;      // [N, 3]
  torch::Tensor opacity_logits;  // [N]; opacity = sigmoid
  torch::Tensor colour_logits;   // [N, C]; colour = sigmoid

  int64_t size() const { return means.defined() ? means.size(0) : 0; }
  std::vector<torch::Tensor*> All() {
    return {&means, &quats, &log_scales, &opacity_logits, &colour_logits};
  }
};

// What a strategy asks the trainer to do after an optimiser step. The
// trainer applies it to the parameters and to its per-Gaussian optimiser
// state (kept rows follow their Gaussian, appended rows start from zero).
struct DensifyPlan {
  torch::Tensor keep;     // [K] int64 rows kept, in order; undefined: no change in size
  GaussianParams append;  // rows added after the kept ones (plain tensors), or empty
  // [A] int64: the row each appended one was cloned or split from, so that a
  // trainer can copy attributes the strategy does not know (a mesh binding).
  torch::Tensor parents;
  // Clamp every opacity to at most this (and restart its optimiser state); 0: no reset.
  double reset_opacity = 0;
  std::string summary;    // a line for the log; empty when nothing happened
};

class DensifyStrategy {
 public:
  virtual ~DensifyStrategy() = default;
  // After the backward pass: the screen-space gradient `means2d_grad` [N, 2]
  // (pixels) and `radii` [N] of the view just rendered, its size in pixels.
  virtual void AfterBackward(const torch::Tensor& means2d_grad, const torch::Tensor& radii,
                             int width, int height) = 0;
  // The statistics AfterBackward gathered since the last AfterStep, `n`
  // rows on `device` (zeros where it gathered none): a data-parallel step
  // sums them over its ranks, in place, before AfterStep, so that every rank
  // densifies alike.
  virtual std::vector<torch::Tensor> StepStatistics(int64_t n, torch::Device device) = 0;
  // After the optimiser step `step` (counting from 1).
  virtual DensifyPlan AfterStep(int step, const GaussianParams& params) = 0;
  // Its running statistics and random state, under names starting `prefix`,
  // so that a resumed fit densifies as an uninterrupted one would.
  virtual void SaveState(const std::string& prefix, Checkpoint* checkpoint) const = 0;
  virtual void LoadState(const std::string& prefix, const Checkpoint& checkpoint) = 0;
};


std::unique_ptr<DensifyStrategy> MakeDefaultDensify(const DefaultDensifyOptions& options);

}  // namespace headforge
