#include "avatar/train/densify.h"

#include <torch/torch.h>

#include <cmath>
#include <sstream>

namespace headforge {
namespace {

class DefaultDensify : public DensifyStrategy {
 public:
  explicit DefaultDensify(const DefaultDensifyOptions& options)
      : options_(options), generator_(at::detail::createCPUGenerator(options.seed)) {}

  void AfterBackward(const torch::Tensor& means2d_grad, const torch::Tensor& radii, int width,
                     int height) override {
    torch::NoGradGuard no_grad;
    const int64_t n = radii.size(0);
    const auto opts = means2d_grad.options().dtype(torch::kFloat64);  // on the Gaussians' device
    StepStatistics(n, means2d_grad.device());
    // In units of half the image, as normalised device coordinates would be.
    const torch::Tensor g = means2d_grad.detach().to(torch::kFloat64) *
                            torch::tensor({0.5 * width, 0.5 * height}, opts);
    const torch::Tensor visible = radii > 0;
    step_grad_ += torch::where(visible, g.norm(2, 1), torch::zeros({1}, opts));
    step_seen_ += visible.to(torch::kFloat64);
  }

  std::vector<torch::Tensor> StepStatistics(int64_t n, torch::Device device) override {
    if (!step_grad_.defined() || step_grad_.size(0) != n) {
      const auto opts = torch::TensorOptions().dtype(torch::kFloat64).device(device);
      step_grad_ = torch::zeros({n}, opts);
      step_seen_ = torch::zeros({n}, opts);
    }
    return {step_grad_, step_seen_};
  }

  DensifyPlan AfterStep(int step, const GaussianParams& params) override {
    torch::NoGradGuard no_grad;
    // The step's statistics into the running sums.
    if (step_grad_.defined()) {
      if (!grad_sum_.defined() || grad_sum_.size(0) != step_grad_.size(0)) {
        grad_sum_ = torch::zeros_like(step_grad_);
        seen_ = torch::zeros_like(step_grad_);
      } else if (grad_sum_.device() != step_grad_.device()) {  // restored from a checkpoint
        grad_sum_ = grad_sum_.to(step_grad_.device());
        seen_ = seen_.to(step_grad_.device());
      }
      grad_sum_ += step_grad_;
      seen_ += step_seen_;
      step_grad_ = step_seen_ = torch::Tensor();
    }
    DensifyPlan plan;
    const bool densify_now = step >= options_.start && step <= options_.stop &&
                             step % options_.interval == 0 && grad_sum_.defined() &&
                             grad_sum_.size(0) == params.size();
    if (densify_now) Densify(params, &plan);
    if (options_.reset_every > 0 && step % options_.reset_every == 0 && step <= options_.stop) {
      plan.reset_opacity = 0.01;
      plan.summary += (plan.summary.empty() ? "" : "; ") + std::string("opacities reset to <= 0.01");
    }
    return plan;
  }

  void SaveState(const std::string& prefix, Checkpoint* c) const override {
    c->Put(prefix + "grad_sum", grad_sum_);
    c->Put(prefix + "seen", seen_);
    c->Put(prefix + "generator", generator_.get_state());
  }

  void LoadState(const std::string& prefix, const Checkpoint& c) override {
    grad_sum_ = seen_ = torch::Tensor();
    if (c.Get(prefix + "grad_sum", &grad_sum_)) c.Get(prefix + "seen", &seen_);
    torch::Tensor state;
    if (c.Get(prefix + "generator", &state)) generator_.set_state(state);
  }

 private:
  void Densify(const GaussianParams& p, DensifyPlan* plan) {
    const int64_t n = p.size();
    const torch::Tensor mean_grad = grad_sum_ / seen_.clamp_min(1);
    const torch::Tensor scales = p.log_scales.detach().exp();
    const torch::Tensor max_scale = std::get<0>(scales.max(1));
    const torch::Tensor opacity = torch::sigmoid(p.opacity_logits.detach());
    const bool room = n < options_.max_gaussians;
    const torch::Tensor hot = room ? mean_grad > options_.grad_threshold
                                   : torch::zeros_like(mean_grad, torch::kBool);
    const torch::Tensor small = max_scale <= options_.split_scale * options_.scene_extent;
    const torch::Tensor clone = hot & small;
    const torch::Tensor split = hot & ~small;
    const torch::Tensor prune = (opacity < options_.prune_opacity) | split;

    const torch::Tensor clone_idx = clone.nonzero().squeeze(1);
    const torch::Tensor split_idx = split.nonzero().squeeze(1);
    // Clones: copies in place (the optimiser moves them apart).
    GaussianParams add;
    add.means = p.means.detach().index_select(0, clone_idx);
    add.quats = p.quats.detach().index_select(0, clone_idx);
    add.log_scales = p.log_scales.detach().index_select(0, clone_idx);
    add.opacity_logits = p.opacity_logits.detach().index_select(0, clone_idx);
    add.colour_logits = p.colour_logits.detach().index_select(0, clone_idx);
    // Splits: two Gaussians drawn inside the parent, 1/1.6 of its size.
    if (split_idx.numel() > 0) {
      const torch::Tensor s = scales.index_select(0, split_idx).repeat({2, 1});
      const torch::Tensor q = p.quats.detach().index_select(0, split_idx).repeat({2, 1});
      const torch::Tensor qn = q / q.norm(2, 1, true);
      const torch::Tensor w = qn.select(1, 0), x = qn.select(1, 1), y = qn.select(1, 2),
                          z = qn.select(1, 3);
      const torch::Tensor rot =
          torch::stack({1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)},
                       1)
              .view({-1, 3, 3});
      const torch::Tensor offset =
          torch::matmul(rot, (Normal(s.sizes(), s.options()) * s).unsqueeze(2)).squeeze(2);
      const torch::Tensor means = p.means.detach().index_select(0, split_idx).repeat({2, 1}) + offset;
      add.means = torch::cat({add.means, means});
      add.quats = torch::cat({add.quats, q});
      add.log_scales = torch::cat({add.log_scales, (s / 1.6).log()});
      add.opacity_logits =
          torch::cat({add.opacity_logits, p.opacity_logits.detach().index_select(0, split_idx).repeat({2})});
      add.colour_logits =
          torch::cat({add.colour_logits, p.colour_logits.detach().index_select(0, split_idx).repeat({2, 1})});
    }
    plan->keep = (~prune).nonzero().squeeze(1);
    plan->append = add;
    plan->parents = torch::cat({clone_idx, split_idx.repeat({2})});
    std::ostringstream line;
    line << "densify: " << clone_idx.numel() << " cloned, " << split_idx.numel() << " split, "
         << (prune.sum().item<int64_t>() - split_idx.numel()) << " pruned -> "
         << plan->keep.numel() + add.size() << " Gaussians";
    plan->summary = line.str();
    grad_sum_ = torch::Tensor();
    seen_ = torch::Tensor();
  }

  // Standard normal draws from the CPU generator (the same numbers on every
  // device), on the device of `options`.
  torch::Tensor Normal(at::IntArrayRef sizes, const torch::TensorOptions& options) {
    return torch::randn(sizes, generator_, options.device(torch::kCPU)).to(options.device());
  }

  DefaultDensifyOptions options_;
  at::Generator generator_;
  torch::Tensor grad_sum_, seen_;  // [N] since the last densification
  torch::Tensor step_grad_, step_seen_;  // [N] this step's, until AfterStep adds them
};

}  // namespace

std::unique_ptr<DensifyStrategy> MakeDefaultDensify(const DefaultDensifyOptions& options) {
  return std::make_unique<DefaultDensify>(options);
}

}  // namespace headforge
