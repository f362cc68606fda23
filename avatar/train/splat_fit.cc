#include "avatar/train/splat_fit.h"

#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>

#include "avatar/metrics/image_metrics.h"
#include "avatar/splat/splat_ops.h"
#include "avatar/train/adam.h"
#include "avatar/train/checkpoint.h"
#include "avatar/train/device.h"
#include "avatar/train/loop.h"
#include "core/interrupt.h"
#include "core/log.h"

namespace headforge {
namespace {

struct Evaluation {
  double psnr = 0, ssim = 0;
  std::vector<double> view_psnr;
  std::vector<torch::Tensor> renders;
};

// Renders come back on the CPU.
Evaluation Evaluate(const GaussianParams& params, const std::vector<PosedImage>& views,
                    const SplatOptions& splat) {
  Evaluation e;
  for (const PosedImage& v : views) {
    const torch::Tensor render = RenderFitted(params, v.camera, splat);
    const double psnr = Psnr(render, v.image);
    e.view_psnr.push_back(psnr);
    e.psnr += psnr / views.size();
    e.ssim += Ssim(render, v.image).item<double>() / views.size();
    e.renders.push_back(render.cpu());
  }
  return e;
}

// The views with their images on `device`.
std::vector<PosedImage> OnDevice(const std::vector<PosedImage>& views, torch::Device device) {
  std::vector<PosedImage> out = views;
  for (PosedImage& v : out) v.image = v.image.to(device);
  return out;
}

}  // namespace

Status ParseSplatFitDevice(const std::string& name, torch::Device* device) {
  return ParseDevice("splat-fit", name, device);
}

bool SplatFitOptions::Check(std::string* why) const {
  if (iterations < 1) {
    *why = "iterations must be at least 1";
    return false;
  }
  if (!(ssim_weight >= 0 && ssim_weight <= 1)) {
    *why = "ssim_weight must be in [0, 1]";
    return false;
  }
  if (!(lr_means >= 0 && lr_quats >= 0 && lr_scales >= 0 && lr_opacity >= 0 && lr_colours >= 0)) {
    *why = "learning rates must be zero or positive";
    return false;
  }
  if (!(init_opacity > 0 && init_opacity < 1)) {
    *why = "init_opacity must be in (0, 1)";
    return false;
  }
  if (log_every < 1 || eval_every < 0) {
    *why = "log_every must be >= 1 and eval_every >= 0";
    return false;
  }
  if (checkpoint_every < 1) {
    *why = "checkpoint_every must be at least 1";
    return false;
  }
  return splat.Check(why);
}

torch::Tensor RenderFitted(const GaussianParams& params, const SplatCamera& camera,
                           const SplatOptions& options) {
  torch::NoGradGuard no_grad;
  SplatRenderOptions render;
  render.splat = options;
  return RenderGaussians(params.means, params.quats, params.log_scales,
                         torch::sigmoid(params.opacity_logits), torch::sigmoid(params.colour_logits),
                         {}, camera, render)
      .image.clamp(0, 1);
}

namespace {

const char* const kParamNames[] = {"means", "quats", "log_scales", "opacity_logits", "colour_logits"};

Status SaveFitCheckpoint(const fs::path& path, GaussianParams& p, const Adam& adam,
                         const DensifyStrategy& densify, const at::Generator& gen, const torch::Tensor& order,
                         const LoopState& state) {
  Checkpoint c;
  state.Save(&c);
  const auto params = p.All();
  for (size_t i = 0; i < params.size(); ++i) c.Put(kParamNames[i], *params[i]);
  adam.Save("adam.", &c);
  densify.SaveState("densify.", &c);
  c.Put("generator", gen.get_state());
  c.Put("order", order);
  return c.Save(path);
}

// Restores what SaveFitCheckpoint wrote; `stats` is cut back to the lines the
// checkpoint had seen.
Status LoadFitCheckpoint(const fs::path& path, torch::Device device, GaussianParams* p, Adam* adam,
                         DensifyStrategy* densify, at::Generator* gen, torch::Tensor* order, LoopState* state,
                         StatsLog* stats) {
  Checkpoint c;
  HF_RETURN_IF_ERROR(Checkpoint::Load(path, &c));
  torch::Tensor generator;
  bool ok = state->Load(c) && c.Get("generator", &generator);
  const auto params = p->All();
  for (size_t i = 0; ok && i < params.size(); ++i) {
    ok = c.Get(kParamNames[i], params[i]);
    if (ok) *params[i] = params[i]->to(device).requires_grad_(true);
  }
  if (!ok || !adam->Load("adam.", c))
    return Status::DataError(path.string() + " is not a splat-fit checkpoint; delete it to start over");
  densify->LoadState("densify.", c);
  gen->set_state(generator);
  if (!c.Get("order", order)) *order = torch::Tensor();
  return stats->Truncate(state->stats_lines);
}

}  // namespace

namespace {

// The initial Gaussians: at `init`'s points, unrotated, isotropic at its
// sizes, of opacity `init_opacity`, in its colours; trainable.
void InitialiseGaussians(const InitPoints& init, double init_opacity, torch::Device device, GaussianParams* p) {
  torch::NoGradGuard no_grad;
  const int64_t n = init.positions.size(0);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32).device(device);
  p->means = init.positions.to(opts).clone();
  p->quats = torch::zeros({n, 4}, opts);
  p->quats.select(1, 0).fill_(1.0);
  p->log_scales = init.sizes.to(opts).clamp_min(1e-6).log().unsqueeze(1).repeat({1, 3});
  p->opacity_logits = torch::full({n}, std::log(init_opacity / (1 - init_opacity)), opts);
  p->colour_logits = torch::logit(init.colours.to(opts).clamp(0.01, 0.99));
  for (torch::Tensor* t : p->All()) t->requires_grad_(true);
}

// One step on `view`: render, the L1 + SSIM loss, its gradient, Adam, then
// densification's plan (clone, split, prune, opacity reset) carried out on
// the Gaussians and the optimiser's moments.
void FitStep(const SplatFitOptions& options, const PosedImage& view, const SplatRenderOptions& render_options,
             int step, GaussianParams* p, Adam* adam, DensifyStrategy* densify, RunningStats* stats) {
  const auto out = RenderGaussians(p->means, p->quats, p->log_scales, torch::sigmoid(p->opacity_logits),
                                   torch::sigmoid(p->colour_logits), {}, view.camera, render_options);
  out.means2d.retain_grad();
  const torch::Tensor l1 = (out.image - view.image).abs().mean();
  const torch::Tensor loss =
      (1 - options.ssim_weight) * l1 + options.ssim_weight * (1 - Ssim(out.image, view.image));
  const double value = loss.item<double>();
  stats->Add("loss", value);
  if (!std::isfinite(value)) return;
  loss.backward();
  densify->AfterBackward(out.means2d.grad(), out.radii, view.camera.width, view.camera.height);
  adam->Step();
  adam->ZeroGrad();
  const DensifyPlan plan = densify->AfterStep(step, *p);
  if (plan.keep.defined()) {
    adam->Edit(plan.keep, {plan.append.means, plan.append.quats, plan.append.log_scales,
                           plan.append.opacity_logits, plan.append.colour_logits});
  }
  if (plan.reset_opacity > 0) {
    torch::NoGradGuard no_grad;
    const double cap = std::log(plan.reset_opacity / (1 - plan.reset_opacity));
    p->opacity_logits.clamp_max_(cap);
    adam->ResetMoments(3);
  }
  if (!plan.summary.empty()) HF_LOG(Debug) << "splat-fit step " << step << ": " << plan.summary;
  stats->Add("l1", l1.item<double>());
}

// splat-fit's side of the training loop.
class FitLoop : public LoopTrainer {
 public:
  FitLoop(const SplatFitOptions& options, const std::vector<PosedImage>& train, const std::vector<PosedImage>& test,
          GaussianParams* p, Adam* adam, DensifyStrategy* densify, at::Generator* gen)
      : options_(options), train_(train), test_(test), p_(p), adam_(adam), densify_(densify), gen_(gen) {
    render_.splat = options.splat;
  }
  void Step(int step, RunningStats* stats) override {
    const int64_t slot = (step - 1) % int64_t(train_.size());
    if (slot == 0) order = torch::randperm(int64_t(train_.size()), *gen_);
    const PosedImage& view = train_[size_t(order[slot].item<int64_t>())];
    const double extent = options_.densify.scene_extent;
    adam_->SetLr(0, options_.lr_means * extent * std::pow(0.01, double(step) / options_.iterations));
    FitStep(options_, view, render_, step, p_, adam_, densify_, stats);
  }
  std::string DivergenceAdvice() const override {
    return "lower the learning rates (--lr-means, --lr-scales) or start from smaller Gaussians";
  }
  void Describe(int, nlohmann::json* line) override { (*line)["gaussians"] = p_->size(); }
  bool Evaluate(int step, nlohmann::json* line) override {
    if (test_.empty()) return false;
    const Evaluation e = headforge::Evaluate(*p_, test_, options_.splat);
    (*line)["test_psnr"] = e.psnr;
    (*line)["test_ssim"] = e.ssim;
    (*line)["gaussians"] = p_->size();
    HF_LOG(Info) << "splat-fit: step " << step << ", " << p_->size() << " Gaussians, held-out PSNR " << e.psnr
                 << " dB";
    return true;
  }
  Status Save(const LoopState& state) override {
    return SaveFitCheckpoint(options_.checkpoint_path, *p_, *adam_, *densify_, *gen_, order, state);
  }

  torch::Tensor order;  // the current pass's view order

 private:
  const SplatFitOptions& options_;
  const std::vector<PosedImage>& train_;
  const std::vector<PosedImage>& test_;
  GaussianParams* p_;
  Adam* adam_;
  DensifyStrategy* densify_;
  at::Generator* gen_;
  SplatRenderOptions render_;
};

}  // namespace

Status FitSplats(const SplatFitOptions& options, const std::vector<PosedImage>& train,
                 const std::vector<PosedImage>& test, const InitPoints& init, StatsLog* stats,
                 Progress* progress, SplatFitResult* result) {
  std::string why;
  if (!options.Check(&why)) return Status::InvalidArgument("splat-fit: " + why);
  if (train.empty()) return Status::InvalidArgument("splat-fit: no training views");
  if (!init.positions.defined() || init.positions.size(0) == 0) {
    return Status::InvalidArgument("splat-fit: no initial points");
  }
  torch::Device device = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseSplatFitDevice(options.device, &device));
  const std::vector<PosedImage> train_views = OnDevice(train, device);
  const std::vector<PosedImage> test_views = OnDevice(test, device);
  GaussianParams& p = result->params;
  InitialiseGaussians(init, options.init_opacity, device, &p);
  const double extent = options.densify.scene_extent;
  Adam adam;
  adam.Add(&p.means, options.lr_means * extent, true);
  adam.Add(&p.quats, options.lr_quats, true);
  adam.Add(&p.log_scales, options.lr_scales, true);
  adam.Add(&p.opacity_logits, options.lr_opacity, true);
  adam.Add(&p.colour_logits, options.lr_colours, true);
  const auto densify = MakeDefaultDensify(options.densify);
  auto gen = at::detail::createCPUGenerator(options.seed);
  FitLoop fit(options, train_views, test_views, &p, &adam, densify.get(), &gen);
  LoopState state;
  const fs::path checkpoint = options.checkpoint_path;
  std::error_code ec;
  if (!checkpoint.empty() && fs::exists(checkpoint, ec)) {
    HF_RETURN_IF_ERROR(
        LoadFitCheckpoint(checkpoint, device, &p, &adam, densify.get(), &gen, &fit.order, &state, stats));
    HF_LOG(Info) << "splat-fit: resuming from the checkpoint at step " << state.step << " (" << p.size()
                 << " Gaussians)";
  }
  result->resumed_from = state.step;
  LoopOptions loop;
  loop.label = "splat-fit";
  loop.what = "splat-fit";
  loop.steps = options.iterations;
  loop.max_minutes = options.max_minutes;
  loop.log_every = options.log_every;
  loop.eval_every = options.eval_every;
  loop.checkpoint_every = checkpoint.empty() ? 0 : options.checkpoint_every;
  if (checkpoint.empty()) loop.resume_hint = "no checkpoint kept";
  HF_RETURN_IF_ERROR(RunLoop(loop, &fit, &state, stats, progress));
  result->steps = state.step;
  result->train_seconds = state.seconds;
  progress->Finish(std::to_string(result->steps) + " steps, " + std::to_string(p.size()) +
                   " Gaussians");
  if (!test.empty()) {
    Evaluation e = Evaluate(p, test_views, options.splat);
    result->test_psnr = e.psnr;
    result->test_ssim = e.ssim;
    result->view_psnr = e.view_psnr;
    result->test_renders = std::move(e.renders);
    stats->Append(nlohmann::json{{"step", result->steps}, {"test_psnr", e.psnr}, {"test_ssim", e.ssim},
                                 {"gaussians", p.size()}, {"seconds", result->train_seconds}, {"final", true}}
                      .dump());
  }
  for (torch::Tensor* t : p.All()) *t = t->detach().cpu();
  return Status::Ok();
}

}  // namespace headforge
