// The gaussian-style avatar's stage 3 (decoder.h), in four phases over one
// step count, checkpointed as one run:
//   prior:  the generator trained unconditionally on the training frames
//           (non-saturating GAN loss, lazy R1, ADA), the subject's own prior;
//   invert: PTI's first half, a latent per extreme-pose frame fitted with the
//           generator fixed (L1, D-SSIM and the prior discriminator's features);
//   tune:   PTI's second half, the generator fine-tuned on those frames at
//           their latents; the decoder's w becomes their mean;
//   fuse:   the generator frozen (unless full-tune), the encoder, the
//           projections and the Gaussians' networks trained on every view
//           with L1 + D-SSIM + feature matching + a discriminator that sees
//           the image beside the tracked mesh's UV map.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <utility>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/metrics/image_metrics.h"
#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"
#include "avatar/nn/functional.h"
#include "avatar/splat/splat_ops.h"
#include "avatar/train/adam.h"
#include "avatar/train/adversarial.h"
#include "avatar/train/checkpoint.h"
#include "avatar/train/gan_watch.h"
#include "avatar/train/image_file.h"
#include "avatar/train/loop.h"
#include "avatar/train_loop_options.h"
#include "core/log.h"

namespace headforge {
namespace {

namespace F = torch::nn::functional;

enum class Phase { kPrior, kInvert, kTune, kFuse };
const char* PhaseName(Phase p) {
  switch (p) {
    case Phase::kPrior: return "prior";
    case Phase::kInvert: return "pti-invert";
    case Phase::kTune: return "pti-tune";
    case Phase::kFuse: return "fuse";
  }
  return "";
}

// `image` [C, H, W] resized to `canvas`'s image and placed on its square, `fill` around it -> [1, C, S, S].
torch::Tensor OnCanvas(const torch::Tensor& image, const SquareCanvas& canvas, double fill) {
  torch::Tensor resized = image.unsqueeze(0);
  if (image.size(2) > canvas.width) {
    resized = F::interpolate(resized, F::InterpolateFuncOptions()
                                          .size(std::vector<int64_t>{canvas.height, canvas.width})
                                          .mode(torch::kArea));
  } else if (image.size(2) < canvas.width || image.size(1) != canvas.height) {
    resized = nn::ResizeBilinear(resized, canvas.height, canvas.width);
  }
  torch::Tensor out = torch::full({1, image.size(0), canvas.camera.height, canvas.camera.width}, fill, image.options());
  out.slice(2, canvas.y0, canvas.y0 + canvas.height).slice(3, canvas.x0, canvas.x0 + canvas.width).copy_(resized);
  return out;
}

// The discriminator's feature matching: the mean L1 between its block
// features of `a` and `b` (b's taken as constant), each normalised by b's mean magnitude.
torch::Tensor FeatureMatching(nn::DiscriminatorImpl& d, const torch::Tensor& a, const torch::Tensor& b) {
  const std::vector<torch::Tensor> fa = d.Features(a);
  std::vector<torch::Tensor> fb;
  {
    torch::NoGradGuard no_grad;
    fb = d.Features(b);
  }
  torch::Tensor sum = torch::zeros({}, a.options());
  for (size_t i = 0; i < fa.size(); ++i) sum = sum + (fa[i] - fb[i]).abs().mean() / (fb[i].abs().mean() + 1e-3);
  return sum / double(fa.size());
}

void SetTrainable(const std::vector<torch::Tensor>& params, bool on) {
  for (torch::Tensor t : params) t.requires_grad_(on);
}

class DecoderTrainer : public LoopTrainer {
 public:
  DecoderTrainer(const TrainOptions& options, const AvatarDataset& data, GaussianStyleAvatar* avatar)
      : options_(options), data_(data), avatar_(avatar),
        device_(avatar->gaussians.params.means.device()), gen_(at::detail::createCPUGenerator(options.seed + 3)),
        adam_prior_g_(0.0, 0.99), adam_prior_d_(0.0, 0.99), adam_fuse_d_(0.0, 0.99),
        ada_prior_(options.ada_target), ada_fuse_(options.ada_target), prior_watch_(options.collapse_steps),
        fuse_watch_(options.collapse_steps) {
    side_ = stage3_.decoder_resolution > 0 ? stage3_.decoder_resolution : options.data.resolution;
    prior_end_ = stage3_.decoder_init.empty() ? stage3_.prior_steps : 0;
    invert_end_ = prior_end_ + (stage3_.full_tune ? 0 : stage3_.pti_steps);
    tune_end_ = invert_end_ + (stage3_.full_tune ? 0 : stage3_.pti_steps);
    total_ = tune_end_ + stage3_.decoder_steps;
  }

  Status Start(const fs::path& checkpoint, const fs::path& stage2_checkpoint, StatsLog* stats);
  Status Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats, Progress* progress);
  double seconds() const { return state_.seconds; }

  // The loop's side (loop.h).
  void Step(int step, RunningStats* stats) override;
  std::string DivergenceAdvice() const override { return "lower --lr-network or --adversarial-weight"; }
  void Describe(int step, nlohmann::json* line) override;
  bool Boundary(int step) const override { return step == total_ || PhaseOf(step + 1) != PhaseOf(step); }
  bool Evaluate(int step, nlohmann::json* line) override;
  Status Preview(int step) override { return WritePreview(out_dir_ / "previews", step); }
  Status Save(const LoopState& state) override { return SaveCheckpoint(checkpoint_, state); }
  std::string TakeWarning() override { return std::exchange(warning_, std::string()); }

 private:
  Phase PhaseOf(int step) const {
    return step <= prior_end_ ? Phase::kPrior
           : step <= invert_end_ ? Phase::kInvert
           : step <= tune_end_ ? Phase::kTune
                               : Phase::kFuse;
  }
  torch::Tensor Target(const AvatarView& view) const;  // [1, 3, S, S], the head over grey
  torch::Tensor UvMap(const AvatarView& view) const;   // [1, 3, S, S]: u, v, covered in [-1, 1]
  void PriorStep(int step, RunningStats* stats);
  void InvertOrTune(bool tune, RunningStats* stats);
  void FuseStep(int step, RunningStats* stats);
  // The discriminator's step on `real` and `fake` (detached), with lazy R1;
  // its accuracies go to the stats and to `watch`.
  void DiscriminatorStep(nn::DiscriminatorImpl& d, Adam& adam, nn::AdaController& ada, CollapseWatch& watch,
                         const std::string& what, const torch::Tensor& real, const torch::Tensor& fake, int step,
                         RunningStats* stats);
  void ChoosePtiFrames();
  Status SaveCheckpoint(const fs::path& path, const LoopState& state) const;
  Status LoadCheckpoint(const fs::path& path, StatsLog* stats);
  Status WritePreview(const fs::path& dir, int step);

  TrainOptions options_;
  const GaussianStyleTrainOptions& style_ = options_.gaussian_style;  // the model's own part of options_
  const DecoderTrainOptions& stage3_ = style_.decoder;
  const AvatarDataset& data_;
  GaussianStyleAvatar* avatar_;
  torch::Device device_;
  at::Generator gen_;
  int side_ = 0, prior_end_ = 0, invert_end_ = 0, tune_end_ = 0, total_ = 0;
  nn::Discriminator prior_d_{nullptr}, fuse_d_{nullptr};
  std::vector<torch::Tensor> generator_params_, prior_d_params_, fuse_params_, fuse_d_params_;
  torch::Tensor pti_w_;                  // [k, w_dim]
  std::vector<int64_t> pti_views_;       // training views PTI fits
  std::vector<int64_t> usable_;          // training views with reliable tracking
  Adam adam_prior_g_, adam_prior_d_, adam_invert_, adam_tune_, adam_fuse_, adam_fuse_d_;
  nn::AdaController ada_prior_, ada_fuse_;
  CollapseWatch prior_watch_, fuse_watch_;
  std::string warning_;                  // a collapse warning to log at the end of the step
  LoopState state_;
  torch::Tensor order_;
  fs::path out_dir_, checkpoint_;
};

torch::Tensor DecoderTrainer::Target(const AvatarView& view) const {
  const SquareCanvas canvas = MakeSquareCanvas(view.view, side_);
  const torch::Tensor shown = view.image * view.mask + kDecoderBackground * (1 - view.mask);
  return OnCanvas(shown, canvas, kDecoderBackground).to(device_);
}

torch::Tensor DecoderTrainer::UvMap(const AvatarView& view) const {
  torch::Tensor map = (view.uv_map.to(device_, torch::kFloat32) * (2.0 / 255) - 1).unsqueeze(0);
  // Maps drawn at another side (a pack written for another decoder size) are resized.
  if (map.size(2) != side_) map = nn::ResizeBilinear(map, side_, side_);
  return map;
}

void DecoderTrainer::ChoosePtiFrames() {
  // The head's rotation (the condition's first two columns) of each usable
  // view; the farthest from the mean first, then each next the farthest
  // from those chosen.
  const int64_t e = int64_t(data_.expression_names.size());
  std::vector<torch::Tensor> rows;
  for (int64_t i : usable_) rows.push_back(data_.train[size_t(i)].condition.slice(0, e, e + 6));
  const torch::Tensor r = torch::stack(rows).to(torch::kFloat64);
  torch::Tensor nearest = (r - r.mean(0, true)).norm(2, 1);
  const int k = std::min<int>(stage3_.pti_frames, int(usable_.size()));
  for (int j = 0; j < k; ++j) {
    const int64_t pick = nearest.argmax().item<int64_t>();
    pti_views_.push_back(usable_[size_t(pick)]);
    nearest = torch::minimum(nearest, (r - r[pick]).norm(2, 1));
  }
}

Status DecoderTrainer::Start(const fs::path& checkpoint, const fs::path& stage2_checkpoint, StatsLog* stats) {
  StyleDecoderOptions architecture;
  architecture.feature_channels = avatar_->model->options().feature_channels;
  architecture.generator.resolution = side_;
  architecture.projected_blocks = stage3_.projected_blocks;
  torch::manual_seed(uint64_t(options_.seed) + 3);
  avatar_->decoder = StyleDecoder(architecture);
  StyleDecoderImpl& decoder = *avatar_->decoder;
  if (!stage3_.decoder_init.empty())
    HF_RETURN_IF_ERROR(LoadGeneratorWeights(stage3_.decoder_init, decoder.generator.get()).WithContext("train"));
  nn::DiscriminatorOptions d;
  d.resolution = side_;
  d.channels = 16;
  d.max_channels = 128;
  d.in_channels = 3;
  prior_d_ = nn::Discriminator(d);
  d.in_channels = 6;  // the image, then the UV map (u, v, covered)
  fuse_d_ = nn::Discriminator(d);
  decoder.to(device_);
  prior_d_->to(device_);
  fuse_d_->to(device_);

  // The Gaussians stay as stages 1-2 left them; their networks go on learning.
  for (torch::Tensor* t : avatar_->gaussians.params.All()) *t = t->detach();
  generator_params_ = decoder.generator->parameters();
  prior_d_params_ = prior_d_->parameters();
  fuse_d_params_ = fuse_d_->parameters();
  fuse_params_ = decoder.FusionParameters();
  for (const torch::Tensor& t : avatar_->model->parameters()) fuse_params_.push_back(t);
  if (stage3_.full_tune)
    for (const torch::Tensor& t : generator_params_) fuse_params_.push_back(t);
  for (torch::Tensor& t : generator_params_) adam_prior_g_.Add(&t, options_.lr_discriminator, false);
  for (torch::Tensor& t : generator_params_) adam_tune_.Add(&t, options_.lr_network * 0.2, false);
  for (torch::Tensor& t : prior_d_params_) adam_prior_d_.Add(&t, options_.lr_discriminator, false);
  for (torch::Tensor& t : fuse_params_) adam_fuse_.Add(&t, options_.lr_network, false);
  for (torch::Tensor& t : fuse_d_params_) adam_fuse_d_.Add(&t, options_.lr_discriminator, false);
  decoder.w.requires_grad_(false);

  std::string note;
  usable_ = UsableTrainingViews(data_, &note);
  if (usable_.empty()) return Status::DataError("train: no reliably tracked training view for stage 3");
  if (stage3_.adversarial_weight > 0)
    for (int64_t i : usable_)
      if (!data_.train[size_t(i)].uv_map.defined())
        return Status::InvalidArgument("train: stage 3's discriminator needs the training views' UV maps "
                                       "(DatasetOptions::uv_map_side)");
  ChoosePtiFrames();
  {
    // PTI starts from the mean latent; without PTI it is the decoder's w.
    torch::NoGradGuard no_grad;
    const torch::Tensor z = torch::randn({1024, decoder.options().generator.z_dim}, gen_).to(device_);
    const torch::Tensor mean = decoder.generator->Map(z).mean(0, true);
    pti_w_ = mean.repeat({int64_t(pti_views_.size()), 1}).clone();
  }
  pti_w_.requires_grad_(true);
  adam_invert_.Add(&pti_w_, 0.01, false);

  std::error_code ec;
  if (fs::exists(checkpoint, ec)) {
    HF_RETURN_IF_ERROR(LoadCheckpoint(checkpoint, stats));
  } else {
    // Stage 3's first checkpoint replaces stages 1-2's: from here a resumed
    // run starts at stage 3.
    state_.stats_lines = stats->size();
    HF_RETURN_IF_ERROR(SaveCheckpoint(checkpoint, state_));
  }
  fs::remove(stage2_checkpoint, ec);
  return Status::Ok();
}

void DecoderTrainer::DiscriminatorStep(nn::DiscriminatorImpl& d, Adam& adam, nn::AdaController& ada,
                                       CollapseWatch& watch, const std::string& what, const torch::Tensor& real,
                                       const torch::Tensor& fake, int step, RunningStats* stats) {
  DiscriminatorBatch batch;
  batch.real = real;
  batch.fake = fake;
  batch.colour_channels = 3;
  batch.augment_p = stage3_.decoder_ada ? ada.p() : 0.0;
  const DiscriminatorUpdate u =
      UpdateDiscriminator(d, adam, ada, batch, {options_.r1_gamma, options_.r1_every}, step, gen_);
  stats->Add("d_real_accuracy", u.real_accuracy);
  stats->Add("d_fake_accuracy", u.fake_accuracy);
  if (watch.Observe(u.real_accuracy, u.fake_accuracy)) warning_ = watch.Warning(what);
  stats->Add("loss_d", u.loss);
}

void DecoderTrainer::PriorStep(int step, RunningStats* stats) {
  StyleDecoderImpl& decoder = *avatar_->decoder;
  const int64_t batch = options_.batch;
  const torch::Tensor z = torch::randn({batch, decoder.options().generator.z_dim}, gen_).to(device_);
  const torch::Tensor fake = decoder.Generate(decoder.generator->Map(z), &gen_) * 2 - 1;
  std::vector<torch::Tensor> reals;
  for (int64_t b = 0; b < batch; ++b) {
    const int64_t pick = torch::randint(int64_t(usable_.size()), {1}, gen_).item<int64_t>();
    reals.push_back(Target(data_.train[size_t(usable_[size_t(pick)])]));
  }
  const torch::Tensor real = torch::cat(reals) * 2 - 1;
  const double p = stage3_.decoder_ada ? ada_prior_.p() : 0.0;
  const torch::Tensor loss_g = F::softplus(-prior_d_->forward(nn::Augment(fake, p, 3, gen_))).mean();
  loss_g.backward();
  adam_prior_g_.Step();
  adam_prior_g_.ZeroGrad();
  adam_prior_d_.ZeroGrad();
  DiscriminatorStep(*prior_d_, adam_prior_d_, ada_prior_, prior_watch_, "stage 3's prior", real, fake, step, stats);
  adam_prior_g_.ZeroGrad();
  stats->Add("loss", loss_g.item<double>());
}

void DecoderTrainer::InvertOrTune(bool tune, RunningStats* stats) {
  StyleDecoderImpl& decoder = *avatar_->decoder;
  std::vector<torch::Tensor> targets;
  for (int64_t i : pti_views_) targets.push_back(Target(data_.train[size_t(i)]));
  const torch::Tensor target = torch::cat(targets);
  const torch::Tensor out = decoder.Generate(tune ? pti_w_.detach() : pti_w_);
  const torch::Tensor l1 = (out - target).abs().mean();
  torch::Tensor loss = (1 - style_.ssim_weight) * l1 + style_.ssim_weight * (1 - Ssim(out, target));
  if (stage3_.perceptual_weight > 0 && prior_end_ > 0)
    loss = loss + stage3_.perceptual_weight * FeatureMatching(*prior_d_, out * 2 - 1, target * 2 - 1);
  loss.backward();
  Adam& adam = tune ? adam_tune_ : adam_invert_;
  adam.Step();
  adam.ZeroGrad();
  adam_prior_d_.ZeroGrad();
  stats->Add("l1", l1.item<double>());
  stats->Add("loss", loss.item<double>());
}

void DecoderTrainer::FuseStep(int step, RunningStats* stats) {
  StyleDecoderImpl& decoder = *avatar_->decoder;
  const int64_t views = int64_t(usable_.size());
  const int64_t slot = (step - tune_end_ - 1) % views;
  if (slot == 0) order_ = torch::randperm(views, gen_);
  const int64_t index = usable_[size_t(order_[slot].item<int64_t>())];
  const AvatarView& view = data_.train[size_t(index)];
  PosedGaussians posed = avatar_->Pose(data_, view, data_.TrainingLatent(view), avatar_->deform);
  if (avatar_->pose_corrections.defined()) posed = CorrectPose(posed, avatar_->pose_corrections[index]);
  const SquareCanvas canvas = MakeSquareCanvas(view.view, side_);
  torch::Tensor background = torch::zeros({posed.features.size(1)}, posed.features.options());
  background.slice(0, 0, 3).fill_(kDecoderBackground);
  const torch::Tensor splat = RenderGaussians(posed.means, posed.quats, posed.log_scales, posed.opacities,
                                              posed.features, background, canvas.camera)
                                  .image;
  const torch::Tensor out = decoder.forward(splat.unsqueeze(0));
  const torch::Tensor target = Target(view);
  const torch::Tensor l1 = (out - target).abs().mean();
  torch::Tensor loss = (1 - style_.ssim_weight) * l1 + style_.ssim_weight * (1 - Ssim(out, target));
  const bool adversarial = stage3_.adversarial_weight > 0;
  torch::Tensor fake, real;
  if (adversarial) {
    const torch::Tensor uv = UvMap(view);
    fake = torch::cat({out * 2 - 1, uv}, 1);
    real = torch::cat({target * 2 - 1, uv}, 1);
    const double p = stage3_.decoder_ada ? ada_fuse_.p() : 0.0;
    loss = loss + stage3_.adversarial_weight * F::softplus(-fuse_d_->forward(nn::Augment(fake, p, 3, gen_))).mean();
    if (stage3_.perceptual_weight > 0) loss = loss + stage3_.perceptual_weight * FeatureMatching(*fuse_d_, fake, real);
  }
  const double value = loss.item<double>();
  stats->Add("loss", value);
  if (!std::isfinite(value)) return;
  loss.backward();
  adam_fuse_.Step();
  adam_fuse_.ZeroGrad();
  if (adversarial) {
    adam_fuse_d_.ZeroGrad();
    DiscriminatorStep(*fuse_d_, adam_fuse_d_, ada_fuse_, fuse_watch_, "stage 3's fusion", real, fake, step, stats);
    adam_fuse_.ZeroGrad();
  }
  stats->Add("l1", l1.item<double>());
}

Status DecoderTrainer::WritePreview(const fs::path& dir, int step) {
  torch::NoGradGuard no_grad;
  StyleDecoderImpl& decoder = *avatar_->decoder;
  torch::Tensor image;
  if (PhaseOf(step) == Phase::kPrior) {
    // Four samples of the prior.
    auto preview = at::detail::createCPUGenerator(7);
    const torch::Tensor z = torch::randn({4, decoder.options().generator.z_dim}, preview).to(device_);
    const torch::Tensor samples = decoder.Generate(decoder.generator->Map(z)).clamp(0, 1).cpu();
    image = torch::cat(samples.unbind(0), 2);
  } else if (PhaseOf(step) != Phase::kFuse) {
    // PTI's fits beside their frames.
    std::vector<torch::Tensor> rows;
    const torch::Tensor fits = decoder.Generate(pti_w_).clamp(0, 1).cpu();
    for (size_t k = 0; k < pti_views_.size(); ++k)
      rows.push_back(torch::cat({fits[int64_t(k)], Target(data_.train[size_t(pti_views_[k])])[0].cpu()}, 2));
    image = torch::cat(rows, 1);
  } else {
    const std::vector<AvatarView>& views = data_.test.empty() ? data_.train : data_.test;
    const AvatarView& view = views.front();
    const torch::Tensor grey = torch::full({3}, kDecoderBackground, torch::TensorOptions().device(device_));
    const PosedGaussians posed = avatar_->Pose(data_, view, 0, avatar_->deform);
    const torch::Tensor splatted = RenderRgb(posed, view.view, grey).clamp(0, 1).cpu();
    const torch::Tensor decoded = avatar_->Draw(posed, view.view, grey).clamp(0, 1).cpu();
    image = torch::cat({splatted, decoded, view.image * view.mask + kDecoderBackground * (1 - view.mask)}, 2);
  }
  char name[48];
  std::snprintf(name, sizeof(name), "stage3_%s_%06d.png", PhaseName(PhaseOf(step)), step);
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  return WriteTensorImage(dir / name, image);
}

Status DecoderTrainer::SaveCheckpoint(const fs::path& path, const LoopState& state) const {
  Checkpoint c;
  state.Save(&c);
  c.PutModule("model.", *avatar_->model);
  c.PutModule("decoder.", *avatar_->decoder);
  c.PutModule("prior_d.", *prior_d_);
  c.PutModule("fuse_d.", *fuse_d_);
  c.Put("pti_w", pti_w_);
  adam_prior_g_.Save("adam_prior_g.", &c);
  adam_prior_d_.Save("adam_prior_d.", &c);
  adam_invert_.Save("adam_invert.", &c);
  adam_tune_.Save("adam_tune.", &c);
  adam_fuse_.Save("adam_fuse.", &c);
  adam_fuse_d_.Save("adam_fuse_d.", &c);
  c.Put("ada_prior", torch::tensor(ada_prior_.State(), torch::kFloat64));
  c.Put("ada_fuse", torch::tensor(ada_fuse_.State(), torch::kFloat64));
  c.Put("generator", gen_.get_state());
  c.Put("order", order_);
  c.Put("collapse_runs", torch::tensor({double(prior_watch_.run()), double(fuse_watch_.run())}, torch::kFloat64));
  return c.Save(path);
}

Status DecoderTrainer::LoadCheckpoint(const fs::path& path, StatsLog* stats) {
  Checkpoint c;
  HF_RETURN_IF_ERROR(Checkpoint::Load(path, &c));
  const Status damaged =
      Status::DataError(path.string() + " is not this stage 3's checkpoint; delete it to start stage 3 over");
  torch::Tensor generator, ada_prior, ada_fuse, pti_w, runs;
  if (!state_.Load(c) || !c.Get("generator", &generator) || !c.Get("pti_w", &pti_w) ||
      !c.Get("ada_prior", &ada_prior) || !c.Get("ada_fuse", &ada_fuse) || !pti_w.sizes().equals(pti_w_.sizes()) ||
      !c.Get("collapse_runs", &runs) || runs.numel() != 2)
    return damaged;
  if (!c.GetModule("model.", avatar_->model.get()) || !c.GetModule("decoder.", avatar_->decoder.get()) ||
      !c.GetModule("prior_d.", prior_d_.get()) || !c.GetModule("fuse_d.", fuse_d_.get()))
    return damaged;
  {
    torch::NoGradGuard no_grad;
    pti_w_.copy_(pti_w);
  }
  if (!adam_prior_g_.Load("adam_prior_g.", c) || !adam_prior_d_.Load("adam_prior_d.", c) ||
      !adam_invert_.Load("adam_invert.", c) || !adam_tune_.Load("adam_tune.", c) ||
      !adam_fuse_.Load("adam_fuse.", c) || !adam_fuse_d_.Load("adam_fuse_d.", c))
    return damaged;
  const auto values = [](const torch::Tensor& t) {
    return std::vector<double>(t.data_ptr<double>(), t.data_ptr<double>() + t.numel());
  };
  ada_prior_.Restore(values(ada_prior));
  ada_fuse_.Restore(values(ada_fuse));
  const std::vector<double> run = values(runs);
  prior_watch_.set_run(int(run[0]));
  fuse_watch_.set_run(int(run[1]));
  gen_.set_state(generator);
  if (!c.Get("order", &order_)) order_ = torch::Tensor();
  if (state_.step > 0)
    HF_LOG(Info) << "train: resuming stage 3 from its checkpoint at step " << state_.step << " of " << total_;
  return stats->Truncate(state_.stats_lines);
}

void DecoderTrainer::Step(int step, RunningStats* stats) {
  StyleDecoderImpl& decoder = *avatar_->decoder;
  const Phase phase = PhaseOf(step);
  // Only the phase's own parameters take gradients.
  SetTrainable(generator_params_, phase == Phase::kPrior || phase == Phase::kTune ||
                                      (phase == Phase::kFuse && stage3_.full_tune));
  if (phase == Phase::kFuse && step == tune_end_ + 1) {
    torch::NoGradGuard no_grad;
    decoder.w.copy_(pti_w_.mean(0, true));  // PTI's latents, or the mean latent without PTI
  }
  switch (phase) {
    case Phase::kPrior: PriorStep(step, stats); break;
    case Phase::kInvert: InvertOrTune(false, stats); break;
    case Phase::kTune: InvertOrTune(true, stats); break;
    case Phase::kFuse: FuseStep(step, stats); break;
  }
}

void DecoderTrainer::Describe(int step, nlohmann::json* line) {
  const Phase phase = PhaseOf(step);
  (*line)["phase"] = PhaseName(phase);
  (*line)["augment_p"] = phase == Phase::kPrior ? ada_prior_.p() : ada_fuse_.p();
  for (const char* key : {"loss_d", "l1"})  // zero where the phase has none
    if (!line->contains(key)) (*line)[key] = 0.0;
}

bool DecoderTrainer::Evaluate(int step, nlohmann::json* line) {
  // Held out as the avatar draws them once fusion trains the decoder on the
  // splats; the prior and PTI phases draw nothing of the avatar yet.
  if (PhaseOf(step) != Phase::kFuse) return false;
  StyleDecoderImpl& decoder = *avatar_->decoder;
  decoder.eval();
  const ViewScores s = MeanScores(EvaluateAvatar(*avatar_, data_, 5, {}));
  decoder.train();
  (*line)["test_psnr_masked"] = s.psnr_masked;
  (*line)["test_ssim_masked"] = s.ssim_masked;
  HF_LOG(Info) << "train: stage 3 step " << step << ", held-out PSNR " << s.psnr_masked
               << " dB over the head (every 5th view)";
  return true;
}

Status DecoderTrainer::Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats,
                             Progress* progress) {
  out_dir_ = out_dir;
  checkpoint_ = checkpoint;
  HF_LOG(Info) << "train: stage 3, the StyleGAN decoder at " << side_ << "x" << side_ << ": "
               << prior_end_ << " prior steps, " << (invert_end_ - prior_end_) << " + " << (tune_end_ - invert_end_)
               << " PTI steps on " << pti_views_.size() << " extreme-pose frames, " << stage3_.decoder_steps
               << " fusion steps" << (stage3_.full_tune ? " (full-tune: the generator trained too)" : "");
  LoopOptions loop = TrainLoopOptions(options_.loop, "train: stage 3", total_);
  loop.what = "stage 3";
  loop.max_minutes = stage3_.decoder_max_minutes;
  loop.tags = {{"stage", 3}};
  HF_RETURN_IF_ERROR(RunLoop(loop, this, &state_, stats, progress));
  if (state_.step < total_)
    HF_LOG(Warning) << "train: stage 3 stopped at the time limit in its " << PhaseName(PhaseOf(state_.step))
                    << " phase (step " << state_.step << " of " << total_
                    << "); give more --decoder-max-minutes or fewer --decoder-steps for a fully trained decoder";
  SetTrainable(generator_params_, false);
  avatar_->decoder->eval();
  progress->Finish(std::to_string(state_.step) + " steps");
  return Status::Ok();
}

}  // namespace

Status TrainStyleDecoder(const TrainOptions& options, const AvatarDataset& data, GaussianStyleAvatar* avatar,
                         const fs::path& out_dir, const fs::path& stage2_checkpoint, StatsLog* stats,
                         Progress* progress, double* seconds) {
  DecoderTrainer trainer(options, data, avatar);
  const fs::path checkpoint = out_dir / "decoder_checkpoint.pt";
  HF_RETURN_IF_ERROR(trainer.Start(checkpoint, stage2_checkpoint, stats));
  HF_RETURN_IF_ERROR(trainer.Train(out_dir, checkpoint, stats, progress));
  *seconds = trainer.seconds();
  return Status::Ok();
}

}  // namespace headforge
