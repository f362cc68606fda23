// The gaussian-style avatar's training loop: stage 1 (canonical Gaussians,
// triplane generator, L1 + D-SSIM on the first three splatted channels), then
// stage 2 (the attention deformation, plus L1 on the eyes' and mouth's
// crops), with densification, checkpoints, stats.jsonl and previews.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/metrics/image_metrics.h"
#include "avatar/splat/splat_ops.h"
#include "avatar/train/adam.h"
#include "avatar/train/device.h"
#include "avatar/train/distributed.h"
#include "avatar/train/image_file.h"
#include "avatar/train/loop.h"
#include "avatar/train_loop_options.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {
namespace {

namespace F = torch::nn::functional;

// Side of the eye and mouth crops of the region loss, pixels.
constexpr int64_t kCropSize = 24;

// The eyes' and mouth's boxes of `view` cut from `image` [3, H, W] and
// resampled to kCropSize^2 (RoI-align with one bilinear sample per cell) -> [R, 3, S, S].
torch::Tensor RegionCrops(const torch::Tensor& image, const AvatarView& view) {
  const int64_t w = image.size(2), h = image.size(1);
  const auto opts = image.options();
  const torch::Tensor cells = (torch::arange(kCropSize, opts) + 0.5) / kCropSize;  // [S]
  std::vector<torch::Tensor> grids;
  for (const auto& box : view.regions) {
    const torch::Tensor x = box[0] + (box[2] - box[0]) * cells, y = box[1] + (box[3] - box[1]) * cells;
    const torch::Tensor u = (x + 0.5) / w * 2 - 1, v = (y + 0.5) / h * 2 - 1;
    grids.push_back(torch::stack({u.unsqueeze(0).expand({kCropSize, kCropSize}),
                                  v.unsqueeze(1).expand({kCropSize, kCropSize})},
                                 2));
  }
  const torch::Tensor grid = torch::stack(grids);  // [R, S, S, 2]
  const torch::Tensor batch = image.unsqueeze(0).expand({grid.size(0), -1, -1, -1});
  return F::grid_sample(batch, grid, F::GridSampleFuncOptions().mode(torch::kBilinear).align_corners(false));
}

const char* const kRowNames[] = {"means", "quats", "log_scales", "opacity_logits", "features"};

class Trainer : public LoopTrainer {
 public:
  Trainer(const TrainOptions& options, const AvatarDataset& data, torch::Device device)
      : options_(options), data_(data), device_(device), gen_(at::detail::createCPUGenerator(options.seed)) {
    group_ = dynamic_cast<ProcessGroup*>(options.collective);  // the only Collective there is
    if (group_) {
      rank_ = group_->rank();
      world_ = group_->world();
    }
    views_per_step_ = style_.views_per_step > 0 ? style_.views_per_step : world_;
    // One state of the head in every view: nothing for a deformation to follow.
    if (data.one_state) options_.gaussian_style.deform = false;
    const int steps = options.loop.steps;
    const int canonical = style_.deform ? int(std::lround(style_.canonical_fraction * steps)) : steps;
    stage1_steps_ = std::clamp(canonical, 0, steps);
  }

  Status Start(const fs::path& checkpoint, StatsLog* stats);
  Status Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats, Progress* progress);
  Status Finish(const fs::path& out_dir, TrainSummary* summary);
  int step() const { return state_.step; }
  bool out_of_time() const { return state_.out_of_time; }
  const GaussianStyleAvatar& avatar() const { return avatar_; }

  // The loop's side (loop.h).
  void Step(int step, RunningStats* stats) override;
  std::string DivergenceAdvice() const override { return "lower --lr-network or --lr-means"; }
  void Describe(int step, nlohmann::json* line) override;
  bool Evaluate(int step, nlohmann::json* line) override;
  Status Preview(int step) override { return WritePreview(out_dir_ / "previews", step); }
  Status Save(const LoopState& state) override { return SaveCheckpoint(checkpoint_, state); }
  bool Done(int step, std::string* why) override;

 private:
  void Densify(int step);
  Status SaveCheckpoint(const fs::path& path, const LoopState& state) const;
  Status LoadCheckpoint(const fs::path& path, StatsLog* stats);
  Status WritePreview(const fs::path& dir, int step);
  bool deform_now(int step) const { return style_.deform && step > stage1_steps_; }

  TrainOptions options_;
  const GaussianStyleTrainOptions& style_ = options_.gaussian_style;  // the model's own part of options_
  const AvatarDataset& data_;
  torch::Device device_;
  at::Generator gen_;
  int stage1_steps_ = 0;
  GaussianStyleAvatar avatar_;
  std::vector<torch::Tensor> network_;  // the networks' parameters, in the optimiser after the rows
  Adam adam_;
  std::unique_ptr<DensifyStrategy> densify_;
  LoopState state_;
  torch::Tensor order_;  // the current pass's view order
  fs::path out_dir_, checkpoint_;
  std::vector<torch::Tensor> images_, masks_;  // the training views' on the device
  std::vector<int64_t> usable_;  // the training views whose tracking is reliable
  double lr_means_ = 0;  // the means' first learning rate; it decays to 1% over the steps
  // [training views, 6]: each one's head-pose correction (--pose-lr), zero at first.
  torch::Tensor pose_corrections_;
  // The validation frames' best masked PSNR in stage 2, its step, and the
  // evaluations since (--validation, --patience).
  double best_validation_ = -1;
  int best_validation_step_ = 0, since_best_ = 0;
  int stopped_at_ = 0;  // > 0: stopped there by --patience
  // A data-parallel run's ranks (null: one process), this one's rank, and
  // the training views of each step over all ranks.
  ProcessGroup* group_ = nullptr;
  int rank_ = 0, world_ = 1, views_per_step_ = 1;
};

Status Trainer::Start(const fs::path& checkpoint, StatsLog* stats) {
  GaussianStyleOptions architecture;
  architecture.feature_channels = options_.feature_channels;
  architecture.triplane.latent_dim = options_.latent_dim;
  architecture.triplane.resolution = options_.triplane_resolution;
  architecture.expressions = int64_t(data_.expression_names.size());
  architecture.mesh_riding = style_.mesh_riding;
  if (data_.one_state && rank_ == 0)
    HF_LOG(Info) << "train: stage 1 alone (a still head, one expression: no deformation to learn)";
  torch::manual_seed(uint64_t(options_.seed));  // the networks' initial weights
  avatar_.model = GaussianStyle(architecture, data_.num_frames);
  avatar_.deform = style_.deform;
  if (style_.mesh_riding) avatar_.neutral = ComputeTriangleFrames(data_.identity_vertices, data_.triangles);
  HF_RETURN_IF_ERROR(InitGaussians(data_, options_, avatar_, &avatar_.gaussians));
  avatar_.model->to(device_);
  if (style_.mesh_riding) avatar_.neutral = avatar_.neutral.To(device_);
  GaussianParams& p = avatar_.gaussians.params;
  for (torch::Tensor* t : p.All()) *t = t->to(device_).requires_grad_(true);
  if (avatar_.gaussians.binding.defined()) avatar_.gaussians.binding = avatar_.gaussians.binding.to(device_);
  // Gaussian parameters live in metres (canonical) or in their triangles'
  // sizes (riding, about 2.5 mm): the extent scales position steps and the
  // size beyond which densification splits rather than clones.
  const double extent = style_.mesh_riding ? 100.0 : 0.3;
  lr_means_ = style_.lr_means * extent;
  adam_.Add(&p.means, lr_means_, true);
  adam_.Add(&p.quats, style_.lr_quats, true);
  adam_.Add(&p.log_scales, style_.lr_scales, true);
  adam_.Add(&p.opacity_logits, style_.lr_opacity, true);
  adam_.Add(&p.colour_logits, style_.lr_features, true);
  network_ = avatar_.model->parameters();
  for (torch::Tensor& t : network_) adam_.Add(&t, options_.lr_network, false);
  if (style_.pose_lr > 0) {
    pose_corrections_ = torch::zeros({int64_t(data_.train.size()), 6}, torch::TensorOptions().device(device_));
    pose_corrections_.requires_grad_(true);
    adam_.Add(&pose_corrections_, style_.pose_lr, false);
  }
  DefaultDensifyOptions densify;
  densify.start = style_.densify_from;
  densify.stop = style_.densify_until;
  densify.interval = style_.densify_every;
  densify.reset_every = 0;
  densify.grad_threshold = style_.grad_threshold;
  densify.max_gaussians = style_.max_gaussians;
  densify.scene_extent = extent;
  densify.seed = uint64_t(options_.seed) + 1;
  densify_ = MakeDefaultDensify(densify);
  for (size_t i = 0; i < data_.train.size(); ++i) {
    images_.push_back(data_.train[i].image.to(device_));
    masks_.push_back(data_.train[i].mask.to(device_));
  }
  // Frames the tracker interpolated or flagged would teach the deformation
  // the wrong expression: they are left out.
  std::string note;
  usable_ = UsableTrainingViews(data_, &note);
  if (!note.empty() && rank_ == 0)
    HF_LOG(Warning) << "train: " << note;
  else if (usable_.size() < data_.train.size() && rank_ == 0)
    HF_LOG(Info) << "train: " << data_.train.size() - usable_.size() << " of " << data_.train.size()
                 << " training views left out (tracking interpolated or low-confidence)";
  if (usable_.empty())
    return Status::DataError("train: the tracker found the face in no training frame (every one interpolated); "
                             "check overlay_<camera>.mp4 and run headforge track again, give frontal cameras, or "
                             "train --model gan-avatar, which trains without tracked expressions");
  std::error_code ec;
  if (fs::exists(checkpoint, ec)) HF_RETURN_IF_ERROR(LoadCheckpoint(checkpoint, stats));
  return Status::Ok();
}

void Trainer::Step(int step, RunningStats* stats) {
  if (step == stage1_steps_ + 1 && style_.deform && rank_ == 0)
    HF_LOG(Info) << "train: stage 2 (deformation" << (style_.region_weight > 0 ? ", region loss" : "")
                 << ") from step " << step;
  const int64_t views = int64_t(usable_.size());
  adam_.SetLr(0, lr_means_ * std::pow(0.01, double(step) / options_.loop.steps));
  const bool stage2 = deform_now(step);
  // The step's views continue the pass's seeded order; of several, rank r of
  // a data-parallel run takes the r-th, (r + W)-th, ... Every rank draws
  // every view's random numbers, so that their generators stay alike.
  const int per_step = views_per_step_;
  const double share = 1.0 / per_step;
  double loss_sum = 0, l1_sum = 0, region_sum = 0;
  for (int j = 0; j < per_step; ++j) {
    const int64_t slot = ((int64_t(step) - 1) * per_step + j) % views;
    if (slot == 0) order_ = torch::randperm(views, gen_);
    const int64_t index = usable_[size_t(order_[slot].item<int64_t>())];
    const AvatarView& view = data_.train[size_t(index)];
    // A random background each step: only the head may be opaque.
    const torch::Tensor background = torch::rand({3}, gen_).to(device_);
    // Frame 0's latent in place of the view's own, for --latent-dropout of them.
    int64_t latent = data_.TrainingLatent(view);
    if (stage2 && style_.latent_dropout > 0 && torch::rand({1}, gen_).item<double>() < style_.latent_dropout)
      latent = 0;
    if (j % world_ != rank_) continue;
    PosedGaussians posed = avatar_.Pose(data_, view, latent, stage2);
    if (pose_corrections_.defined()) posed = CorrectPose(posed, pose_corrections_[index]);
    const SplatRenderResult out = RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities,
                                                  posed.features.slice(1, 0, 3), background, view.view);
    out.means2d.retain_grad();
    const torch::Tensor& mask = masks_[size_t(index)];
    const torch::Tensor target = images_[size_t(index)] * mask + background.view({3, 1, 1}) * (1 - mask);
    const torch::Tensor l1 = (out.image - target).abs().mean();
    torch::Tensor loss = (1 - style_.ssim_weight) * l1 + style_.ssim_weight * (1 - Ssim(out.image, target));
    double region = 0;
    if (stage2 && style_.region_weight > 0 && view.has_landmarks) {
      const torch::Tensor r = (RegionCrops(out.image, view) - RegionCrops(target, view)).abs().mean();
      loss = loss + style_.region_weight * r;
      region = r.item<double>();
    }
    const double value = loss.item<double>();
    loss_sum += value;
    l1_sum += l1.item<double>();
    region_sum += region;
    if (!std::isfinite(value)) continue;
    (per_step == 1 ? loss : loss * share).backward();
    // Densification judges each view's own screen-space gradient, not its
    // share of the step's loss.
    densify_->AfterBackward(per_step == 1 ? out.means2d.grad() : out.means2d.grad() * per_step, out.radii,
                            view.view.width, view.view.height);
  }
  if (group_) {
    // Every rank's gradients and figures summed: a parameter no view of this
    // rank reached takes part as zeros (its gradient is made where another
    // rank's view reached it, as one process with all the views would).
    const std::vector<torch::Tensor*> params = adam_.Parameters();
    std::vector<double> figures;
    for (const torch::Tensor* p : params) figures.push_back(p->grad().defined() ? 1.0 : 0.0);
    figures.insert(figures.end(), {loss_sum, l1_sum, region_sum});
    const torch::Tensor summed = torch::tensor(figures, torch::kFloat64);
    group_->AllReduceSum({summed});
    const double* reached = summed.data_ptr<double>();
    std::vector<torch::Tensor> grads;
    for (size_t i = 0; i < params.size(); ++i) {
      if (reached[i] == 0) continue;
      if (!params[i]->grad().defined()) params[i]->mutable_grad() = torch::zeros_like(*params[i]);
      grads.push_back(params[i]->grad());
    }
    for (const torch::Tensor& t : densify_->StepStatistics(avatar_.gaussians.params.size(), device_)) grads.push_back(t);
    group_->AllReduceSum(grads);
    loss_sum = reached[params.size()];
    l1_sum = reached[params.size() + 1];
    region_sum = reached[params.size() + 2];
  }
  stats->Add("loss", loss_sum * share);
  if (!std::isfinite(loss_sum)) return;
  adam_.Step();
  adam_.ZeroGrad();
  Densify(step);
  stats->Add("l1", l1_sum * share);
  stats->Add("region_l1", region_sum * share);
}

void Trainer::Describe(int step, nlohmann::json* line) {
  (*line)["stage"] = deform_now(step) ? 2 : 1;
  (*line)["gaussians"] = avatar_.gaussians.params.size();
  if (pose_corrections_.defined()) {
    // The corrections' median size: degrees of rotation, millimetres of translation.
    torch::NoGradGuard no_grad;
    const torch::Tensor c = pose_corrections_.detach().cpu();
    (*line)["pose_rotation_deg"] = c.slice(1, 0, 3).norm(2, 1).median().item<double>() * 180 / M_PI;
    (*line)["pose_translation_mm"] = c.slice(1, 3, 6).norm(2, 1).median().item<double>() * 1000;
  }
}

bool Trainer::Evaluate(int step, nlohmann::json* line) {
  // Drawn as the avatar stands at this step; put back after.
  const bool deform = avatar_.deform;
  avatar_.deform = deform_now(step);
  const ViewScores s = MeanScores(EvaluateAvatar(avatar_, data_, 5, {}));
  const double v = data_.validation.empty() ? 0 : MeanScores(EvaluateValidation(avatar_, data_)).psnr_masked;
  avatar_.deform = deform;
  (*line)["test_psnr_masked"] = s.psnr_masked;
  (*line)["test_ssim_masked"] = s.ssim_masked;
  (*line)["gaussians"] = avatar_.gaussians.params.size();
  std::string validation;
  if (!data_.validation.empty()) {
    (*line)["validation_psnr_masked"] = v;
    validation = ", validation " + std::to_string(v).substr(0, 5) + " dB";
    // Only stage 2 counts: stage 1's avatar does not follow the expressions.
    if (deform_now(step)) {
      if (v > best_validation_) {
        best_validation_ = v;
        best_validation_step_ = step;
        since_best_ = 0;
      } else {
        ++since_best_;
      }
    }
  }
  HF_LOG(Info) << "train: step " << step << ", " << avatar_.gaussians.params.size() << " Gaussians, held-out PSNR "
               << s.psnr_masked << " dB over the head (every 5th view)" << validation;
  return true;
}

bool Trainer::Done(int step, std::string* why) {
  if (style_.patience <= 0 || data_.validation.empty() || !deform_now(step) || since_best_ < style_.patience)
    return false;
  char text[200];
  std::snprintf(text, sizeof(text),
                "the validation frames' score has not risen for %d evaluations (best %.2f dB at step %d; --patience)",
                since_best_, best_validation_, best_validation_step_);
  *why = text;
  stopped_at_ = step;
  return true;
}

void Trainer::Densify(int step) {
  GaussianParams& p = avatar_.gaussians.params;
  const DensifyPlan plan = densify_->AfterStep(step, p);
  if (plan.keep.defined()) {
    torch::Tensor& binding = avatar_.gaussians.binding;
    if (binding.defined()) {
      // Clones and splits ride their parent's triangle.
      const torch::Tensor old = binding;
      binding = old.index_select(0, plan.keep);
      if (plan.parents.defined() && plan.parents.numel() > 0)
        binding = torch::cat({binding, old.index_select(0, plan.parents.to(old.device()))});
    }
    adam_.Edit(plan.keep, {plan.append.means, plan.append.quats, plan.append.log_scales, plan.append.opacity_logits,
                           plan.append.colour_logits});
  }
  if (!plan.summary.empty()) HF_LOG(Debug) << "train step " << step << ": " << plan.summary;
}

Status Trainer::WritePreview(const fs::path& dir, int step) {
  if (data_.test.empty()) return Status::Ok();
  torch::NoGradGuard no_grad;
  const AvatarView& view = data_.test.front();
  const torch::Tensor background = torch::full({3}, kEvalBackground, torch::TensorOptions().device(device_));
  const torch::Tensor render =
      avatar_.Draw(avatar_.Pose(data_, view, 0, deform_now(step)), view.view, background).cpu();
  const torch::Tensor target = view.image * view.mask + kEvalBackground * (1 - view.mask);
  char name[32];
  std::snprintf(name, sizeof(name), "step_%06d.png", step);
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  return WriteTensorImage(dir / name, torch::cat({render, target}, 2));
}

Status Trainer::SaveCheckpoint(const fs::path& path, const LoopState& state) const {
  Checkpoint c;
  state.Save(&c);
  GaussianParams p = avatar_.gaussians.params;
  const auto rows = p.All();
  for (size_t i = 0; i < rows.size(); ++i) c.Put(std::string("gaussians.") + kRowNames[i], *rows[i]);
  c.Put("gaussians.binding", avatar_.gaussians.binding);
  if (pose_corrections_.defined()) c.Put("pose_corrections", pose_corrections_);
  c.PutModule("model.", *avatar_.model);
  adam_.Save("adam.", &c);
  densify_->SaveState("densify.", &c);
  c.Put("generator", gen_.get_state());
  c.Put("order", order_);
  if (views_per_step_ != 1) c.Put("views_per_step", int64_t(views_per_step_));  // one: left out, as before
  c.Put("validation.best", best_validation_);
  c.Put("validation.best_step", int64_t(best_validation_step_));
  c.Put("validation.since", int64_t(since_best_));
  return c.Save(path);
}

Status Trainer::LoadCheckpoint(const fs::path& path, StatsLog* stats) {
  Checkpoint c;
  HF_RETURN_IF_ERROR(Checkpoint::Load(path, &c));
  const Status damaged = Status::DataError(path.string() + " is not this training's checkpoint; delete it to start over");
  torch::Tensor generator;
  int64_t best_step = 0, since = 0;
  if (!state_.Load(c) || !c.Get("generator", &generator) || !c.Get("validation.best", &best_validation_) ||
      !c.Get("validation.best_step", &best_step) || !c.Get("validation.since", &since))
    return damaged;
  best_validation_step_ = int(best_step);
  since_best_ = int(since);
  // The pass's order is walked views_per_step at a time: another count
  // would resume elsewhere in it, with other batches.
  int64_t views_per_step = 1;
  c.Get("views_per_step", &views_per_step);
  if (views_per_step != views_per_step_)
    return Status::InvalidArgument(path.string() + " was saved by a training of " + std::to_string(views_per_step) +
                                   " views a step, this one takes " + std::to_string(views_per_step_) +
                                   (world_ > 1 ? " (one per rank)" : "") + ": resume it with --views-per-step " +
                                   std::to_string(views_per_step) + " (or as many ranks), or delete it to start over");
  GaussianParams& p = avatar_.gaussians.params;
  const auto rows = p.All();
  for (size_t i = 0; i < rows.size(); ++i) {
    if (!c.Get(std::string("gaussians.") + kRowNames[i], rows[i])) return damaged;
    *rows[i] = rows[i]->to(device_).requires_grad_(true);
  }
  if (c.Get("gaussians.binding", &avatar_.gaussians.binding))
    avatar_.gaussians.binding = avatar_.gaussians.binding.to(device_);
  if (!c.GetModule("model.", avatar_.model.get())) return damaged;
  if (pose_corrections_.defined()) {
    torch::Tensor corrections;
    if (!c.Get("pose_corrections", &corrections) || !corrections.sizes().equals(pose_corrections_.sizes()))
      return damaged;
    torch::NoGradGuard no_grad;
    pose_corrections_.copy_(corrections);
  }
  if (!adam_.Load("adam.", c)) return damaged;
  densify_->LoadState("densify.", c);
  gen_.set_state(generator);
  if (!c.Get("order", &order_)) order_ = torch::Tensor();
  if (order_.defined() && order_.numel() != int64_t(usable_.size()))
    return Status::DataError(path.string() + " was saved by a training over " + std::to_string(order_.numel()) +
                             " training views, this one trains on " + std::to_string(usable_.size()) +
                             " (the tracking, or which of its frames this version trains on, changed): delete it "
                             "to start over");
  HF_LOG(Info) << "train: resuming from the checkpoint at step " << state_.step << " (" << p.size() << " Gaussians)";
  return stats->Truncate(state_.stats_lines);
}

Status Trainer::Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats, Progress* progress) {
  out_dir_ = out_dir;
  checkpoint_ = checkpoint;
  LoopOptions loop = TrainLoopOptions(options_.loop, "train: gaussian-style", options_.loop.steps);
  // Without stage 3 after it, a run the time limit stopped keeps its
  // checkpoint with the model, for train --extend.
  loop.save_at_time_limit = style_.decoder.decoder_steps <= 0;
  loop.collective = group_;
  if (group_) {
    // Every rank must start where rank 0 starts: the same step (its
    // checkpoint read through the same --out), Gaussians and options.
    const double mine[] = {double(state_.step), double(avatar_.gaussians.params.size()), double(views_per_step_),
                           double(options_.loop.steps)};
    torch::Tensor all = torch::tensor(std::vector<double>(std::begin(mine), std::end(mine)), torch::kFloat64);
    try {
      group_->AllReduceSum({all});
    } catch (const DistributedFailure& e) {
      return Status::IoError(std::string("train: ") + e.what());
    }
    for (int i = 0; i < 4; ++i)
      if (all[i].item<double>() != world_ * mine[i])
        return Status::InvalidArgument(
            "train: the ranks do not start alike (rank " + std::to_string(rank_) + ": step " +
            std::to_string(state_.step) + ", " + std::to_string(avatar_.gaussians.params.size()) + " Gaussians, " +
            std::to_string(views_per_step_) + " views a step, " + std::to_string(options_.loop.steps) +
            " steps); give every rank the same PACK, the same --out on a file system they share, and the same --set");
  }
  if (group_ && rank_ == 0)
    HF_LOG(Info) << "train: data-parallel over " << world_ << " ranks, " << views_per_step_
                 << " training views a step (rank r takes the r-th, (r + " << world_ << ")-th, ...)";
  else if (!group_ && views_per_step_ > 1)
    HF_LOG(Info) << "train: " << views_per_step_ << " training views a step";
  HF_RETURN_IF_ERROR(RunLoop(loop, this, &state_, stats, progress));
  progress->Finish(std::to_string(state_.step) + " steps, " + std::to_string(avatar_.gaussians.params.size()) +
                   " Gaussians");
  avatar_.deform = deform_now(state_.step);
  return Status::Ok();
}

Status Trainer::Finish(const fs::path& out_dir, TrainSummary* summary) {
  if (pose_corrections_.defined()) avatar_.pose_corrections = pose_corrections_.detach().clone();
  nlohmann::json extra = nlohmann::json::object();
  if (!data_.validation.empty()) {
    // The end's own validation score beside the best stage 2 reached.
    const double end = MeanScores(EvaluateValidation(avatar_, data_)).psnr_masked;
    extra["validation"] = {{"views", data_.validation.size()}, {"psnr_masked", end},
                           {"best_psnr_masked", best_validation_}, {"best_step", best_validation_step_},
                           {"stopped_at", stopped_at_}, {"patience", style_.patience}};
  }
  HF_RETURN_IF_ERROR(FinishAvatar(avatar_, options_, data_, out_dir, extra, summary));
  summary->steps = state_.step;
  summary->seconds = state_.seconds;
  if (stopped_at_ > 0)
    summary->note = "stopped at step " + std::to_string(stopped_at_) + " of " + std::to_string(options_.loop.steps) +
                    ": the validation frames' score had stopped rising (--patience " +
                    std::to_string(style_.patience) + ")";
  if (style_.deform && options_.loop.max_minutes > 0 && state_.step <= stage1_steps_ &&
      stage1_steps_ < options_.loop.steps) {
    // The time limit came first: the deformation never trained.
    summary->note = "stage 1 only: the time limit came before stage 2 (step " + std::to_string(stage1_steps_ + 1) +
                    "), so the avatar does not follow the expressions; give more --max-minutes or fewer --steps";
    HF_LOG(Warning) << "train: " << summary->note;
  }
  return Status::Ok();
}

}  // namespace

namespace {

// `views` drawn as the avatar draws them: `training_views` with their own
// latents and pose corrections, others with frame 0's latent.
std::vector<ViewScores> ScoreViews(GaussianStyleAvatar& avatar, const AvatarDataset& data,
                                   const std::vector<AvatarView>& views, int stride, const fs::path& write_dir,
                                   bool training_views) {
  torch::NoGradGuard no_grad;
  const torch::Device device = avatar.gaussians.params.means.device();
  const torch::Tensor background = torch::full({3}, kEvalBackground, torch::TensorOptions().device(device));
  std::vector<ViewScores> scores;
  for (size_t i = 0; i < views.size(); i += size_t(std::max(stride, 1))) {
    const AvatarView& view = views[i];
    // Inference takes frame 0's latent: a held-out frame has none of its own.
    // Training views are scored as trained, with their own.
    const auto start = std::chrono::steady_clock::now();
    PosedGaussians posed = avatar.Pose(data, view, training_views ? data.TrainingLatent(view) : 0, avatar.deform);
    if (training_views && avatar.pose_corrections.defined())
      posed = CorrectPose(posed, avatar.pose_corrections[int64_t(i)]);
    const torch::Tensor render = avatar.Draw(posed, view.view, background).clamp(0, 1).cpu();
    const double ms = 1000 * SecondsSince(start);
    ViewScores s = ScoreRender(render, view.image, view.mask, background.cpu());
    s.render_ms = ms;
    s.frame = view.frame;
    s.camera = view.camera;
    scores.push_back(s);
    if (write_dir.empty()) continue;
    char name[64];
    std::snprintf(name, sizeof(name), "%s_%06d.png", view.camera.c_str(), view.frame);
    WriteTensorImage(write_dir / name, ComparisonStrip(render, view.image, view.mask, kEvalBackground))
        .ok();
  }
  return scores;
}

}  // namespace

std::vector<ViewScores> EvaluateAvatar(GaussianStyleAvatar& avatar, const AvatarDataset& data, int stride,
                                       const fs::path& write_dir, bool training_views) {
  return ScoreViews(avatar, data, training_views ? data.train : data.test, stride, write_dir, training_views);
}

std::vector<ViewScores> EvaluateValidation(GaussianStyleAvatar& avatar, const AvatarDataset& data) {
  return ScoreViews(avatar, data, data.validation, 1, {}, false);
}

int SetValidationAside(double fraction, AvatarDataset* data) {
  if (!(fraction > 0)) return 0;
  std::vector<int> frames;
  for (const AvatarView& v : data->train) frames.push_back(v.frame);
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  const int n = int(frames.size());
  std::set<int> aside;
  if (data->holdout_every > 0) {
    const int stride = HoldoutStride(fraction);
    for (int i = stride / 2; i < n; i += stride) aside.insert(frames[size_t(i)]);
  } else {
    const int count = std::max(1, int(std::lround(fraction * n)));
    for (int i = std::max(0, n - count); i < n; ++i) aside.insert(frames[size_t(i)]);
  }
  if (n - int(aside.size()) < kFewestTrainingFrames) return 0;
  std::vector<AvatarView> kept;
  for (AvatarView& v : data->train) (aside.count(v.frame) ? data->validation : kept).push_back(std::move(v));
  data->train = std::move(kept);
  return int(aside.size());
}

int64_t PruneUnseenGaussians(GaussianStyleAvatar& avatar, const AvatarDataset& data) {
  torch::NoGradGuard no_grad;
  GaussianParams& p = avatar.gaussians.params;
  const int64_t n = p.size();
  if (n == 0 || data.train.empty()) return 0;
  const torch::Device device = p.means.device();
  torch::Tensor seen = torch::zeros({n}, torch::TensorOptions().dtype(torch::kBool).device(device));
  // Each Gaussian is posed on its own (its deformation, its triangle), so a
  // view poses only those no earlier view has shown over the person: after
  // the first views, a few per cent.
  GaussianStyleAvatar open = avatar;
  for (const AvatarView& view : data.train) {
    const torch::Tensor unseen = (~seen).nonzero().view({-1});
    if (unseen.numel() == 0) break;
    const std::vector<torch::Tensor*> from = p.All(), to = open.gaussians.params.All();
    for (size_t k = 0; k < from.size(); ++k) *to[k] = from[k]->index_select(0, unseen);
    if (avatar.gaussians.binding.defined()) open.gaussians.binding = avatar.gaussians.binding.index_select(0, unseen);
    const PosedGaussians posed = open.Pose(data, view, data.TrainingLatent(view), avatar.deform);
    const SplatCamera& c = view.view;
    const torch::Tensor rt = torch::tensor(std::vector<double>(c.cam_from_world.begin(), c.cam_from_world.end()))
                                 .view({3, 4})
                                 .to(torch::kFloat32)
                                 .to(device);
    const torch::Tensor cam = posed.means.matmul(rt.slice(1, 0, 3).t()) + rt.select(1, 3);
    const torch::Tensor z = cam.select(1, 2);
    const torch::Tensor u = (c.fx * cam.select(1, 0) / z + c.cx).round();
    const torch::Tensor v = (c.fy * cam.select(1, 1) / z + c.cy).round();
    const torch::Tensor inside = (z > 0.01) & (u >= 0) & (u < c.width) & (v >= 0) & (v < c.height);
    const torch::Tensor index = (v.clamp(0, c.height - 1) * c.width + u.clamp(0, c.width - 1)).to(torch::kLong);
    const torch::Tensor mask = view.mask.to(device).reshape({-1}) > 0.5;
    seen.index_put_({unseen}, inside & mask.index_select(0, index));
  }
  const torch::Tensor keep = seen.nonzero().view({-1});
  const int64_t pruned = n - keep.numel();
  if (pruned == 0) return 0;
  for (torch::Tensor* t : p.All()) *t = t->detach().index_select(0, keep).requires_grad_(true);
  if (avatar.gaussians.binding.defined()) avatar.gaussians.binding = avatar.gaussians.binding.index_select(0, keep);
  return pruned;
}

Status FinishAvatar(GaussianStyleAvatar& avatar, const TrainOptions& options, const AvatarDataset& data,
                    const fs::path& out_dir, const nlohmann::json& extra, TrainSummary* summary) {
  if (const int64_t pruned = PruneUnseenGaussians(avatar, data); pruned > 0)
    HF_LOG(Info) << "train: " << pruned << " Gaussians no training view shows over the person removed";
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir / "held_out"));
  const std::vector<ViewScores> scores = EvaluateAvatar(avatar, data, 1, out_dir / "held_out");
  const ViewScores mean = MeanScores(scores);
  // How well the training views themselves are fitted (every 10th): set
  // against the held-out figures, it tells underfitting from what the
  // held-out frames bring that training never saw.
  const ViewScores fitted = MeanScores(EvaluateAvatar(avatar, data, 10, {}, true));
  nlohmann::json views = nlohmann::json::array();
  for (const ViewScores& s : scores) views.push_back(ScoresJson(s));
  nlohmann::json eval = {
      {"held_out_frames", data.HeldOutText()},
      {"background", kEvalBackground},
      {"latent_frame", 0},
      {"decoder", bool(avatar.decoder)},
      {"mean", ScoresJson(mean, false)},
      {"training_views", {{"psnr_masked", fitted.psnr_masked}, {"ssim_masked", fitted.ssim_masked}}},
      // Posing and drawing one held-out view, its image back on the CPU,
      // on the training device (the first view, warming up, left out).
      {"render_ms", MeanRenderMs(scores)},
      {"device", options.device},
      {"views", views}};
  eval.update(extra);
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "eval.json", eval, 1));
  HF_RETURN_IF_ERROR(SaveAvatar(avatar, options, data, out_dir));
  summary->gaussians = avatar.gaussians.params.size();
  SetSummaryScores(mean, int(scores.size()), fitted, summary);
  return Status::Ok();
}

Status TrainGaussianStyle(const TrainOptions& options, const AvatarDataset& loaded, const fs::path& out_dir,
                          StatsLog* stats, Progress* progress, TrainSummary* summary) {
  // The validation frames (--validation) leave training here, for every stage.
  AvatarDataset data = loaded;
  const GaussianStyleTrainOptions& style = options.gaussian_style;
  if (style.validation > 0 && options.loop.eval_every > 0 && style.pose_lr > 0) {
    // The pose corrections are kept per training view of the workspace, as
    // render and export load it: a split would shift them.
    HF_LOG(Warning) << "train: --validation is not used with --pose-lr; training on every training frame";
  } else if (style.validation > 0 && options.loop.eval_every > 0) {
    if (const int frames = SetValidationAside(style.validation, &data); frames > 0)
      HF_LOG(Info) << "train: " << frames << " training frames (" << data.validation.size()
                   << " views) set aside as validation frames, to choose when stage 2 stops";
    else
      HF_LOG(Warning) << "train: too few training frames to set any aside for --validation; training on all";
  }
  torch::Device device = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseDevice("train", options.device, &device));
  const fs::path checkpoint = out_dir / "checkpoint.pt", decoder_checkpoint = out_dir / "decoder_checkpoint.pt";
  std::error_code ec;
  GaussianStyleAvatar avatar;
  // A data-parallel run's ranks but rank 0 train stages 1-2 with it and
  // write nothing: rank 0 writes the model and trains stage 3 alone.
  const bool follower = options.collective != nullptr && options.collective->rank() != 0;
  // Stage 3 under way: stages 1-2 are in model.pt and eval_stage2.json.
  if (style.decoder.decoder_steps > 0 && fs::exists(decoder_checkpoint, ec) && !fs::exists(checkpoint, ec)) {
    if (follower) return Status::Ok();
    HF_RETURN_IF_ERROR(LoadAvatar(out_dir, device, &avatar, nullptr));
    avatar.decoder = nullptr;
    if (style.mesh_riding) avatar.neutral = ComputeTriangleFrames(data.identity_vertices, data.triangles).To(device);
    nlohmann::json stage2;
    HF_RETURN_IF_ERROR(ReadJson(out_dir / "eval_stage2.json", &stage2));
    summary->steps = stage2.value("steps", 0);
    summary->seconds = stage2.value("seconds", 0.0);
    summary->resumed_from = summary->steps;
  } else {
    Trainer trainer(options, data, device);
    HF_RETURN_IF_ERROR(trainer.Start(checkpoint, stats));
    const int resumed_from = trainer.step();
    HF_RETURN_IF_ERROR(trainer.Train(out_dir, checkpoint, stats, progress));
    if (follower) {
      summary->steps = trainer.step();
      summary->resumed_from = resumed_from;
      return Status::Ok();
    }
    HF_RETURN_IF_ERROR(trainer.Finish(out_dir, summary));
    summary->resumed_from = resumed_from;
    if (style.decoder.decoder_steps <= 0) {
      // Stopped by the time limit: the checkpoint there stays with the
      // model, and train --extend with a longer limit goes on from it.
      if (trainer.out_of_time() && fs::exists(checkpoint, ec)) {
        summary->extendable = true;
      } else {
        fs::remove(checkpoint, ec);
      }
      return Status::Ok();
    }
    // What stage 3 is measured against.
    nlohmann::json stage2;
    HF_RETURN_IF_ERROR(ReadJson(out_dir / "eval.json", &stage2));
    stage2.erase("views");
    stage2["steps"] = summary->steps;
    stage2["seconds"] = summary->seconds;
    HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "eval_stage2.json", stage2, 1));
    avatar = trainer.avatar();
  }
  double seconds = 0;
  HF_RETURN_IF_ERROR(TrainStyleDecoder(options, data, &avatar, out_dir, checkpoint, stats, progress, &seconds));
  nlohmann::json stage2;
  HF_RETURN_IF_ERROR(ReadJson(out_dir / "eval_stage2.json", &stage2));
  nlohmann::json extra = {{"stage2", stage2.at("mean")}, {"stage3_seconds", seconds}};
  if (stage2.contains("validation")) extra["validation"] = stage2["validation"];  // where stage 2 stopped
  HF_RETURN_IF_ERROR(FinishAvatar(avatar, options, data, out_dir, extra, summary));
  summary->seconds += seconds;
  fs::remove(decoder_checkpoint, ec);
  return Status::Ok();
}

Status TrainGaussianStyleRun(const TrainOptions& options, const AvatarDataset& data, const fs::path& out_dir,
                             Progress* progress, TrainSummary* summary) {
  StatsLog stats;  // a rank but 0's stays in memory
  if (options.collective == nullptr || options.collective->rank() == 0)
    HF_RETURN_IF_ERROR(OpenTrainStats(out_dir, &stats));
  *summary = TrainSummary();
  HF_RETURN_IF_ERROR(TrainGaussianStyle(options, data, out_dir, &stats, progress, summary));
  if (options.collective != nullptr && options.collective->rank() != 0) return Status::Ok();
  summary->outputs = {"model.pt", "config.json", "stats.jsonl", "eval.json"};
  if (summary->extendable) summary->outputs.push_back("checkpoint.pt");
  std::error_code ec;
  for (const char* extra : {"held_out", "previews", "eval_stage2.json"})
    if (fs::exists(out_dir / extra, ec)) summary->outputs.push_back(extra);
  return Status::Ok();
}

}  // namespace headforge
