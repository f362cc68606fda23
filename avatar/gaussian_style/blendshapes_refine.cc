// Gaussian blendshapes refined through the rasterizer against the training
// frames (blendshapes.h: RefineBlendshapes), in the one training loop.
#include <cmath>

#include "avatar/gaussian_style/blendshapes.h"
#include "avatar/metrics/image_metrics.h"
#include "avatar/splat/splat_ops.h"
#include "avatar/train/adam.h"
#include "avatar/train/loop.h"
#include "avatar/train/view_scores.h"
#include "core/log.h"

namespace headforge {

Status BlendshapeRefineOptions::Check() const {
  if (steps < 0) return Status::InvalidArgument("blendshape refinement: steps must be zero or positive");
  if (!(max_minutes >= 0)) return Status::InvalidArgument("blendshape refinement: minutes must be zero or positive");
  if (!(lr_scale > 0) || !(offset_lr_ratio >= 0))
    return Status::InvalidArgument("blendshape refinement: learning rates must be positive");
  if (!(validation > 0 && validation < 1))
    return Status::InvalidArgument("blendshape refinement: the validation fraction must be in (0, 1)");
  if (eval_every < 1) return Status::InvalidArgument("blendshape refinement: eval_every must be at least 1");
  return Status::Ok();
}

namespace {

// The attribute groups of a blendshape row, each with its own step size:
// position 3, rotation 4, log-scale 3, RGB 3 (kBlendshapeAttributes).
constexpr int64_t kGroupStart[] = {0, 3, 7, 10, 13};
constexpr int kGroups = 4;

class BlendshapeRefiner : public LoopTrainer {
 public:
  BlendshapeRefiner(const AvatarDataset& data, const std::vector<size_t>& train, const std::vector<size_t>& validation,
                    const BlendshapeRefineOptions& options, const GaussianBlendshapes& shapes)
      : data_(data), train_(train), validation_(validation), options_(options), gen_(at::detail::createCPUGenerator(options.seed)) {
    k_ = shapes.offsets.size(0);
    // Training's first step sizes in the blendshapes' units (positions over
    // a 0.3 m head, colours through the sigmoid's slope at its middle),
    // scaled by lr_scale (a tenth: the blendshapes already agree with the
    // networks).
    const double lr[kGroups] = {1.6e-4 * 0.3, 1e-3, 5e-3, 2.5e-3 * 0.25};
    for (int g = 0; g < kGroups; ++g) {
      neutral_[g] = shapes.neutral.slice(1, kGroupStart[g], kGroupStart[g + 1]).clone().requires_grad_(true);
      offsets_[g] = shapes.offsets.slice(2, kGroupStart[g], kGroupStart[g + 1]).clone().requires_grad_(true);
    }
    opacity_logits_ = torch::logit(shapes.opacities.clamp(1e-4, 1 - 1e-4)).requires_grad_(true);
    for (int g = 0; g < kGroups; ++g) {
      adam_.Add(&neutral_[g], lr[g] * options.lr_scale, false);
      base_lr_.push_back(lr[g] * options.lr_scale);
    }
    for (int g = 0; g < kGroups; ++g) {
      adam_.Add(&offsets_[g], lr[g] * options.lr_scale * options.offset_lr_ratio, false);
      base_lr_.push_back(lr[g] * options.lr_scale * options.offset_lr_ratio);
    }
    adam_.Add(&opacity_logits_, 5e-2 * options.lr_scale, false);
    base_lr_.push_back(5e-2 * options.lr_scale);
  }

  void Step(int step, RunningStats* stats) override {
    // Linearly down to a tenth of the step size by the last step.
    const double decay = 1.0 - 0.9 * double(step - 1) / std::max(1, options_.steps - 1);
    for (size_t i = 0; i < base_lr_.size(); ++i) adam_.SetLr(i, base_lr_[i] * decay);
    const size_t slot = size_t(step - 1) % train_.size();
    if (slot == 0) order_ = torch::randperm(int64_t(train_.size()), gen_);
    const AvatarView& view = data_.train[train_[size_t(order_[int64_t(slot)].item<int64_t>())]];
    const torch::Tensor background = torch::rand({3}, gen_);
    const PosedGaussians posed = Pose(view.condition.slice(0, 0, k_).to(torch::kFloat32));
    const torch::Tensor image = RenderRgb(posed, view.view, background);
    const torch::Tensor target = view.image * view.mask + background.view({3, 1, 1}) * (1 - view.mask);
    const torch::Tensor l1 = (image - target).abs().mean();
    const torch::Tensor loss = (1 - options_.ssim_weight) * l1 + options_.ssim_weight * (1 - Ssim(image, target));
    const double value = loss.item<double>();
    stats->Add("loss", value);
    if (!std::isfinite(value)) return;
    loss.backward();
    adam_.Step();
    adam_.ZeroGrad();
    stats->Add("l1", l1.item<double>());
  }

  std::string DivergenceAdvice() const override {
    return "export again with fewer refinement steps (--blendshape-refine-steps 0 leaves the fit to the networks)";
  }

  bool Evaluate(int step, nlohmann::json* line) override {
    const double psnr = ValidationPsnr();
    (*line)["validation_psnr_masked"] = psnr;
    curve_.emplace_back(step, psnr);
    if (psnr > best_psnr_) {
      best_psnr_ = psnr;
      best_step_ = step;
      Keep();
    }
    return true;
  }

  // The validation views' mean PSNR over the head as the blendshapes stand.
  double ValidationPsnr() {
    torch::NoGradGuard no_grad;
    const torch::Tensor background = torch::full({3}, kEvalBackground);
    std::vector<ViewScores> scores;
    for (size_t index : validation_) {
      const AvatarView& view = data_.train[index];
      const PosedGaussians posed = Pose(view.condition.slice(0, 0, k_).to(torch::kFloat32));
      scores.push_back(ScoreRender(RenderRgb(posed, view.view, background).clamp(0, 1), view.image, view.mask,
                                   background));
    }
    return MeanScores(scores).psnr_masked;
  }

  // The blendshapes as they stand into `best_` (what the refinement returns
  // unless a later evaluation scores higher).
  void Keep() {
    torch::NoGradGuard no_grad;
    best_.neutral = torch::cat({neutral_[0], neutral_[1], neutral_[2], neutral_[3]}, 1).detach().clone();
    best_.offsets = torch::cat({offsets_[0], offsets_[1], offsets_[2], offsets_[3]}, 2).detach().clone();
    best_.opacities = torch::sigmoid(opacity_logits_).detach().clone();
  }

  // The state before any step: the views set aside score `psnr` on it.
  void Begin(double psnr) {
    best_psnr_ = psnr;
    best_step_ = 0;
    curve_.emplace_back(0, psnr);
    Keep();
  }
  double best_psnr() const { return best_psnr_; }
  int best_step() const { return best_step_; }
  const std::vector<std::pair<int, double>>& curve() const { return curve_; }
  const GaussianBlendshapes& best() const { return best_; }

 private:
  PosedGaussians Pose(const torch::Tensor& weights) const {
    const torch::Tensor w = weights.reshape({1, k_});
    PosedGaussians posed;
    torch::Tensor parts[kGroups];
    for (int g = 0; g < kGroups; ++g) {
      const int64_t width = kGroupStart[g + 1] - kGroupStart[g];
      parts[g] = neutral_[g] + w.matmul(offsets_[g].reshape({k_, -1})).reshape({-1, width});
    }
    posed.means = parts[0];
    posed.quats = parts[1];
    posed.log_scales = parts[2];
    posed.features = parts[3].clamp(0, 1);
    posed.opacities = torch::sigmoid(opacity_logits_);
    return posed;
  }

  const AvatarDataset& data_;
  const std::vector<size_t>& train_;
  const std::vector<size_t>& validation_;
  const BlendshapeRefineOptions& options_;
  at::Generator gen_;
  torch::Tensor order_;
  int64_t k_ = 0;
  torch::Tensor neutral_[kGroups], offsets_[kGroups], opacity_logits_;
  Adam adam_;
  std::vector<double> base_lr_;
  GaussianBlendshapes best_;
  double best_psnr_ = -1;
  std::vector<std::pair<int, double>> curve_;
  int best_step_ = 0;
};

}  // namespace

Status RefineBlendshapes(const AvatarDataset& data, const BlendshapeRefineOptions& options,
                         GaussianBlendshapes* shapes, BlendshapeRefineReport* report, Progress* progress) {
  HF_RETURN_IF_ERROR(options.Check());
  *report = BlendshapeRefineReport();
  if (options.steps == 0) return Status::Ok();
  // Every n-th training view judges the refinement and is not trained on.
  const size_t stride = size_t(std::max(2.0, std::round(1.0 / options.validation)));
  std::vector<size_t> train, validation;
  for (size_t i = 0; i < data.train.size(); ++i) (i % stride == stride / 2 ? validation : train).push_back(i);
  if (validation.empty() || train.empty())
    return Status::InvalidArgument("blendshape refinement: " + std::to_string(data.train.size()) +
                                   " training views are too few to set some aside; export without refinement "
                                   "(--blendshape-refine-steps 0)");
  BlendshapeRefiner refiner(data, train, validation, options, *shapes);
  const auto start = std::chrono::steady_clock::now();
  const double before = refiner.ValidationPsnr();
  refiner.Begin(before);
  LoopOptions loop;
  loop.label = "export: refining the blendshapes";
  loop.what = "the blendshape refinement";
  loop.steps = options.steps;
  loop.max_minutes = options.max_minutes;
  loop.log_every = std::max(1, options.eval_every / 2);
  loop.eval_every = options.eval_every;
  loop.resume_hint = "run the export again";
  LoopState state;
  StatsLog stats;
  HF_RETURN_IF_ERROR(RunLoop(loop, &refiner, &state, &stats, progress));
  nlohmann::json last;
  refiner.Evaluate(state.step, &last);
  report->steps = state.step;
  report->kept_step = refiner.best_step();
  report->validation_views = int(validation.size());
  report->validation_psnr_before = before;
  report->validation_psnr_after = refiner.best_psnr();
  report->seconds = SecondsSince(start);
  report->curve = refiner.curve();
  const GaussianBlendshapes& best = refiner.best();
  shapes->neutral = best.neutral;
  shapes->offsets = best.offsets;
  shapes->opacities = best.opacities;
  HF_LOG(Info) << "export: the blendshapes refined against " << train.size() << " training views for " << state.step
               << " steps in " << report->seconds << " s; the " << validation.size()
               << " views set aside score " << before << " dB before and " << report->validation_psnr_after
               << " dB after (" << (report->kept_step > 0 ? "step " + std::to_string(report->kept_step) + " kept"
                                                          : "no step scored higher: the fit to the networks kept")
               << ")";
  return Status::Ok();
}

Status PruneBlendshapes(const AvatarDataset& data, double fraction, GaussianBlendshapes* shapes,
                        BlendshapePruneReport* report) {
  *report = BlendshapePruneReport();
  const int64_t n = shapes->neutral.size(0), k = shapes->offsets.size(0);
  report->before = report->after = int(n);
  if (!(fraction >= 0 && fraction < 1))
    return Status::InvalidArgument("blendshape pruning: the fraction removed must be in [0, 1)");
  if (fraction == 0 || n == 0) return Status::Ok();
  if (data.train.empty()) return Status::InvalidArgument("blendshape pruning: no training views to weigh them in");
  const auto start = std::chrono::steady_clock::now();
  // Each Gaussian's light: drawn with one channel, its value s_g (1), the
  // image's sum has the derivative sum(alpha T) over pixels by s_g.
  torch::Tensor light = torch::zeros({n}, torch::kFloat64);
  for (const AvatarView& view : data.train) {
    const PosedGaussians posed = PoseBlendshapes(*shapes, view.condition.slice(0, 0, k));
    const torch::Tensor unit = torch::ones({n, 1}, torch::kFloat32).requires_grad_(true);
    const torch::Tensor image = RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities, unit,
                                                torch::zeros({1}), view.view)
                                    .image;
    image.sum().backward();
    light += unit.grad().view({n}).to(torch::kFloat64);
  }
  const int64_t keep = std::max<int64_t>(1, int64_t(std::llround(double(n) * (1 - fraction))));
  const torch::Tensor kept = std::get<0>(std::get<1>(torch::topk(light, keep)).sort());
  const double total = light.sum().item<double>();
  report->light_kept = total > 0 ? light.index_select(0, kept).sum().item<double>() / total : 1;
  shapes->neutral = shapes->neutral.index_select(0, kept).contiguous();
  shapes->offsets = shapes->offsets.index_select(1, kept).contiguous();
  shapes->opacities = shapes->opacities.index_select(0, kept).contiguous();
  report->after = int(keep);
  report->kept.assign(kept.data_ptr<int64_t>(), kept.data_ptr<int64_t>() + keep);
  report->seconds = SecondsSince(start);
  HF_LOG(Info) << "export: " << n - keep << " of " << n << " Gaussians pruned, the least light in "
               << data.train.size() << " training views (the rest give " << 100 * report->light_kept << "% of it) in "
               << report->seconds << " s";
  return Status::Ok();
}

}  // namespace headforge
