// The gan-avatar model's GAN training loop (EG3D's recipe at small scale):
// per step one generator update and one discriminator update on a batch of
// real views and as many generated ones, rendered from cameras drawn from
// the training views.
#include "avatar/gan_avatar/trainer.h"

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <utility>

#include "avatar/gan_avatar/avatar_io.h"
#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"
#include "avatar/nn/functional.h"
#include "avatar/train/adam.h"
#include "avatar/train/adversarial.h"
#include "avatar/train/checkpoint.h"
#include "avatar/train/device.h"
#include "avatar/train/gan_watch.h"
#include "avatar/train/image_file.h"
#include "avatar/train/loop.h"
#include "avatar/train/view_camera.h"
#include "avatar/train/view_scores.h"
#include "avatar/train_loop_options.h"
#include "core/interrupt.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/stats_log.h"

namespace headforge {
namespace {

namespace F = torch::nn::functional;

// The background of the real images (outside their masks) and of the
// renders (where the volume is transparent); also the evaluation's.
constexpr double kBackground = 0.5;
constexpr int64_t kRenderBatch = 8;  // renders drawn at once outside training
// A blendshape the frames read back with this correlation to their tracked
// weights is one the landmark reading sees at the model's resolution.
constexpr double kReadableCorrelation = 0.5;
// Padding of the head's box round the tracked mesh, metres (hair).
constexpr double kBoxPadding = 0.04;
// The running mean of w follows the batches' with this weight.
constexpr double kWAverageRate = 0.01;
// Adam's step for the warm-up's per-frame latents.
constexpr double kCodeLearningRate = 1e-2;

class GanTrainer : public LoopTrainer {
 public:
  GanTrainer(const TrainOptions& options, const AvatarDataset& data, torch::Device device)
      : options_(options), data_(data), device_(device), gen_(at::detail::createCPUGenerator(options.seed)),
        adam_g_(0.0, 0.99), adam_d_(0.0, 0.99), ada_(options.ada_target), watch_(options.collapse_steps) {}

  Status Start(const fs::path& checkpoint, StatsLog* stats);
  // The generator of a finished training (options.generator_from) in place
  // of this one's; Train then trains no GAN.
  Status ImportGenerator(const fs::path& dir);
  Status Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats, Progress* progress);
  Status TrainMapping(const ImageTracker& track_images, StatsLog* stats, Progress* progress);
  // Whether the mapping's renders show the expressions that drive them: the
  // reliably tracked frames of the camera the mapping learnt from (training
  // and held out alike: the mapping learnt from the GAN's renders, never from
  // a frame) drive it with their tracked expressions, the renders are read
  // back by the landmark model and tracker, beside one render of the mean
  // latent (a mapping that ignored its input) and the frames themselves at
  // the model's resolution (what the reading can show at that size).
  Status CheckMappedExpressions(const ImageTracker& track_images, Progress* progress);
  // The latents z the mapping's renders come from ([mapping_samples,
  // z_dim]), or undefined for random ones (drawn batch by batch from `random`).
  torch::Tensor MappingCodes(at::Generator& random) const;
  // The training views' frames, ascending, once each: the rows of
  // frame_codes_ the reconstruction loss fits.
  torch::Tensor TrainingFrames() const;
  Status Finish(const fs::path& out_dir, TrainSummary* summary);
  int step() const { return state_.step; }

  // The GAN loop's side (loop.h).
  void Step(int step, RunningStats* stats) override;
  std::string DivergenceAdvice() const override {
    return "lower --lr-network and --lr-discriminator or raise --r1-gamma";
  }
  void Describe(int step, nlohmann::json* line) override;
  bool Evaluate(int step, nlohmann::json* line) override;
  Status Preview(int step) override { return WritePreview(out_dir_ / "previews", step); }
  Status Save(const LoopState& state) override { return SaveCheckpoint(checkpoint_, state); }
  std::string TakeWarning() override { return std::exchange(warning_, std::string()); }

 private:
  class MappingLoop;
  // The reconstruction loss of a batch of training views: each view's frame
  // from its own camera with a latent of its frame's own (L1 on the image
  // and on the raw render).
  torch::Tensor ReconstructionLoss(RunningStats* stats);
  bool reconstructing(int step) const { return step <= options_.reconstruction_steps; }
  // The discriminator's input: the image and the raw render brought to its size.
  torch::Tensor DualImage(const torch::Tensor& image, const torch::Tensor& raw) const {
    return torch::cat({image, nn::ResizeBilinear(raw, image.size(2), image.size(3))}, 1);
  }
  // Held-out views (or every `stride`-th training view) driven by their
  // tracked expressions through the mapping, or with the mean latent before
  // there is one or when `mean_latent`.
  std::vector<ViewScores> Evaluate(const fs::path& write_dir, int stride, bool mean_latent = false,
                                   bool training_views = false);
  // The training view seen most nearly from the front.
  const AvatarView& FrontalView() const;
  Status WritePreview(const fs::path& dir, int step);
  Status SaveCheckpoint(const fs::path& path, const LoopState& state) const;
  Status LoadCheckpoint(const fs::path& path, StatsLog* stats);
  SplatCamera RenderCamera(const AvatarView& view) const { return view.view.Downscaled(double(data_.width) / render_w_); }
  torch::Tensor RenderMean(const std::vector<SplatCamera>& cameras);
  // Renders of the latents `w` ([M, w_dim]) from `camera` at the output
  // size, a batch at a time: [M, 3, H, W] on the CPU, in [0, 1].
  torch::Tensor RenderLatents(const torch::Tensor& w, const SplatCamera& camera);

  TrainOptions options_;
  const AvatarDataset& data_;
  torch::Device device_;
  at::Generator gen_;
  GanAvatarOptions arch_;
  GanAvatar avatar_;  // the generator, the mapping (after the GAN) and the mean latent, as render draws them
  nn::Discriminator discriminator_{nullptr};
  std::vector<torch::Tensor> g_params_, d_params_;
  Adam adam_g_, adam_d_;
  nn::AdaController ada_;
  CollapseWatch watch_;
  std::string warning_;                   // a collapse warning to log at the end of the step
  torch::Tensor frame_codes_;             // [frames, z_dim]: the warm-up's latent per frame
  bool codes_trained_ = false;            // the training frames' rows of frame_codes_ were fitted
  double mapping_loss_ = 0;               // the mapping's last loss
  RenderExpressions samples_;
  nlohmann::json expression_check_;       // CheckMappedExpressions' figures, for eval.json
  torch::Tensor reals_, conditions_;      // [N, 3, H, W] over the background; [N, 16]
  int render_w_ = 0, render_h_ = 0;
  LoopState state_;
  fs::path out_dir_, checkpoint_;
};

Status GanTrainer::Start(const fs::path& checkpoint, StatsLog* stats) {
  GanRenderSize(options_, data_, &render_w_, &render_h_);
  arch_ = GanArchitecture(options_, data_);
  torch::manual_seed(uint64_t(options_.seed));  // the networks' initial weights
  avatar_.generator = GanGenerator(arch_);
  nn::DiscriminatorOptions d;
  d.in_channels = 6;
  d.resolution = std::max(data_.width, data_.height);
  d.channels = 32;
  d.condition_dim = 16;
  discriminator_ = nn::Discriminator(d);
  avatar_.generator->to(device_);
  discriminator_->to(device_);
  g_params_ = avatar_.generator->parameters();
  d_params_ = discriminator_->parameters();
  for (torch::Tensor& t : g_params_) adam_g_.Add(&t, options_.lr_network, false);
  for (torch::Tensor& t : d_params_) adam_d_.Add(&t, options_.lr_discriminator, false);
  frame_codes_ = torch::randn({data_.num_frames, arch_.z_dim}).to(device_).requires_grad_(true);
  adam_g_.Add(&frame_codes_, kCodeLearningRate, false);
  avatar_.w_average = torch::zeros({arch_.w_dim}, torch::TensorOptions().device(device_));
  avatar_.render_width = render_w_;
  avatar_.render_height = render_h_;
  avatar_.out_width = data_.width;
  avatar_.out_height = data_.height;
  avatar_.background = kBackground;
  avatar_.expressions = int64_t(data_.expression_names.size());
  std::vector<torch::Tensor> reals, conditions;
  for (const AvatarView& view : data_.train) {
    reals.push_back(view.image * view.mask + kBackground * (1 - view.mask));
    conditions.push_back(CameraCondition(view.view));
  }
  reals_ = torch::stack(reals).to(device_);
  conditions_ = torch::stack(conditions).to(device_);
  std::error_code ec;
  if (fs::exists(checkpoint, ec)) HF_RETURN_IF_ERROR(LoadCheckpoint(checkpoint, stats));
  return Status::Ok();
}

torch::Tensor GanTrainer::ReconstructionLoss(RunningStats* stats) {
  const int64_t batch = options_.batch, views = int64_t(data_.train.size());
  const torch::Tensor index = torch::randint(views, {batch}, gen_, torch::kLong);
  std::vector<SplatCamera> cameras;
  std::vector<int64_t> frames;
  for (int64_t b = 0; b < batch; ++b) {
    const AvatarView& view = data_.train[size_t(index[b].item<int64_t>())];
    cameras.push_back(RenderCamera(view));
    frames.push_back(view.frame);
  }
  const torch::Tensor codes = frame_codes_.index_select(0, torch::tensor(frames, torch::kLong).to(device_));
  const torch::Tensor w = avatar_.generator->Map(codes);
  const GanRender out = avatar_.generator->Render(w, cameras, data_.width, data_.height, kBackground, &gen_);
  const torch::Tensor real = reals_.index_select(0, index.to(device_));
  // The super-resolved image and the raw render both: the volume learns the
  // head's shape and colour directly, not only through the super-resolution.
  const torch::Tensor l1 = (out.image - real).abs().mean() +
                           (out.raw - nn::ResizeBilinear(real, render_h_, render_w_)).abs().mean();
  {
    torch::NoGradGuard no_grad;
    avatar_.w_average.lerp_(w.detach().mean(0), kWAverageRate);
  }
  stats->Add("recon_l1", l1.item<double>());
  return l1;
}

void GanTrainer::Step(int step, RunningStats* stats) {
  if (step == options_.reconstruction_steps + 1 && options_.reconstruction_steps > 0)
    HF_LOG(Info) << "train: gan-avatar: adversarial training from step " << step;
  if (reconstructing(step)) {
    ReconstructionLoss(stats).backward();
    adam_g_.Step();
    adam_g_.ZeroGrad();
    return;
  }
  const int64_t batch = options_.batch, views = int64_t(data_.train.size());
  const torch::Tensor real_index = torch::randint(views, {batch}, gen_, torch::kLong);
  const torch::Tensor fake_index = torch::randint(views, {batch}, gen_, torch::kLong);
  const torch::Tensor z = torch::randn({batch, arch_.z_dim}, gen_).to(device_);
  std::vector<SplatCamera> cameras;
  for (int64_t b = 0; b < batch; ++b) cameras.push_back(RenderCamera(data_.train[size_t(fake_index[b].item<int64_t>())]));
  const torch::Tensor fake_c = conditions_.index_select(0, fake_index.to(device_));
  const double p = ada_.p();

  // Generator: make the discriminator call the renders real.
  const torch::Tensor w = avatar_.generator->Map(z);
  const GanRender fake = avatar_.generator->Render(w, cameras, data_.width, data_.height, kBackground, &gen_);
  const torch::Tensor fake_dual = DualImage(fake.image, fake.raw);
  const torch::Tensor loss_g = F::softplus(-discriminator_->forward(nn::Augment(fake_dual, p, 6, gen_), fake_c)).mean();
  // After the warm-up the adversarial loss comes in over --adversarial-ramp
  // steps, while the reconstruction goes on at --recon-weight.
  const int since = step - options_.reconstruction_steps;
  const double ramp = options_.adversarial_ramp > 0 ? std::min(1.0, double(since) / options_.adversarial_ramp) : 1.0;
  torch::Tensor total = ramp * loss_g;
  if (options_.recon_weight > 0) total = total + options_.recon_weight * ReconstructionLoss(stats);
  total.backward();
  adam_g_.Step();
  adam_g_.ZeroGrad();
  adam_d_.ZeroGrad();

  // Discriminator: the same renders (detached) as fake, a batch of frames as real.
  DiscriminatorBatch d;
  const torch::Tensor real = reals_.index_select(0, real_index.to(device_));
  d.real = DualImage(real, nn::ResizeBilinear(real, render_h_, render_w_));
  d.fake = fake_dual;
  d.real_condition = conditions_.index_select(0, real_index.to(device_));
  d.fake_condition = fake_c;
  d.colour_channels = 6;
  d.augment_p = p;
  const DiscriminatorUpdate u =
      UpdateDiscriminator(*discriminator_, adam_d_, ada_, d, {options_.r1_gamma, options_.r1_every}, step, gen_);
  adam_g_.ZeroGrad();
  {
    torch::NoGradGuard no_grad;
    avatar_.w_average.lerp_(w.detach().mean(0), kWAverageRate);
  }
  if (u.has_r1) stats->Add("r1", u.r1);
  stats->Add("loss_g", loss_g.item<double>());
  stats->Add("loss_d", u.loss);
  stats->Add("d_real_accuracy", u.real_accuracy);
  stats->Add("d_fake_accuracy", u.fake_accuracy);
  if (watch_.Observe(u.real_accuracy, u.fake_accuracy)) warning_ = watch_.Warning("the gan-avatar model");
}

void GanTrainer::Describe(int step, nlohmann::json* line) {
  (*line)["phase"] = reconstructing(step) ? "reconstruction" : "adversarial";
  (*line)["augment_p"] = ada_.p();
  (*line)["ada_rt"] = ada_.rt();
  // Every line names every figure (zero where the phase has none), as the report and tests read them.
  for (const char* key : {"recon_l1", "loss_g", "loss_d", "r1", "d_real_accuracy", "d_fake_accuracy"})
    if (!line->contains(key)) (*line)[key] = 0.0;
}

bool GanTrainer::Evaluate(int step, nlohmann::json* line) {
  const ViewScores s = MeanScores(Evaluate({}, 5));
  (*line)["test_psnr_masked"] = s.psnr_masked;
  (*line)["test_ssim_masked"] = s.ssim_masked;
  HF_LOG(Info) << "train: step " << step << ", held-out PSNR of the mean latent " << s.psnr_masked
               << " dB over the head (every 5th view), augmentation p " << ada_.p();
  return true;
}

torch::Tensor GanTrainer::RenderMean(const std::vector<SplatCamera>& cameras) {
  const torch::Tensor w = avatar_.w_average.unsqueeze(0).expand({int64_t(cameras.size()), -1});
  return avatar_.generator->Render(w, cameras, data_.width, data_.height, kBackground, nullptr).image.clamp(0, 1).cpu();
}

const AvatarView& GanTrainer::FrontalView() const {
  size_t best = 0;
  double best_cos = -2;
  for (size_t i = 0; i < data_.train.size(); ++i) {
    // The face looks along +z of the head frame, where the camera sits at c.
    const Eigen::Vector3d c = CameraPose(data_.train[i].view).inverse().translation();
    const double cos = c.z() / c.norm();
    if (cos > best_cos) {
      best_cos = cos;
      best = i;
    }
  }
  return data_.train[best];
}

std::vector<ViewScores> GanTrainer::Evaluate(const fs::path& write_dir, int stride, bool mean_latent,
                                             bool training_views) {
  const torch::Tensor background = torch::full({3}, kBackground);
  const std::vector<AvatarView>& views = training_views ? data_.train : data_.test;
  std::vector<ViewScores> scores;
  for (size_t i = 0; i < views.size(); i += size_t(std::max(stride, 1))) {
    const AvatarView& view = views[i];
    const torch::Tensor render = avatar_.Draw(mean_latent ? torch::Tensor() : view.condition, view.view);
    ViewScores s = ScoreRender(render, view.image, view.mask, background);
    s.frame = view.frame;
    s.camera = view.camera;
    scores.push_back(s);
    if (write_dir.empty()) continue;
    char name[64];
    std::snprintf(name, sizeof(name), "%s_%06d.png", view.camera.c_str(), view.frame);
    WriteTensorImage(write_dir / name, ComparisonStrip(render, view.image, view.mask, kBackground)).ok();
  }
  return scores;
}

torch::Tensor GanTrainer::RenderLatents(const torch::Tensor& w, const SplatCamera& camera) {
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> images;
  for (int64_t first = 0; first < w.size(0); first += kRenderBatch) {
    const int64_t n = std::min<int64_t>(kRenderBatch, w.size(0) - first);
    images.push_back(avatar_.generator
                         ->Render(w.narrow(0, first, n).to(device_, torch::kFloat32),
                                  std::vector<SplatCamera>(size_t(n), camera), data_.width, data_.height, kBackground,
                                  nullptr)
                         .image.clamp(0, 1)
                         .cpu());
  }
  return torch::cat(images);
}

Status GanTrainer::WritePreview(const fs::path& dir, int step) {
  torch::NoGradGuard no_grad;
  // Four random latents (the same every preview) from four training cameras,
  // over the mean latent from the same cameras.
  at::Generator fixed = at::detail::createCPUGenerator(uint64_t(options_.seed) + 7);
  const int64_t n = 4;
  std::vector<SplatCamera> cameras;
  for (int64_t k = 0; k < n; ++k)
    cameras.push_back(RenderCamera(data_.train[size_t(k * int64_t(data_.train.size()) / n)]));
  const torch::Tensor z = torch::randn({n, arch_.z_dim}, fixed).to(device_);
  const torch::Tensor random =
      avatar_.generator->Render(avatar_.generator->Map(z), cameras, data_.width, data_.height, kBackground, nullptr).image;
  const torch::Tensor mean = RenderMean(cameras);
  const torch::Tensor top = torch::cat(random.clamp(0, 1).cpu().unbind(0), 2);
  const torch::Tensor bottom = torch::cat(mean.unbind(0), 2);
  char name[32];
  std::snprintf(name, sizeof(name), "step_%06d.png", step);
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  return WriteTensorImage(dir / name, torch::cat({top, bottom}, 1));
}

Status GanTrainer::SaveCheckpoint(const fs::path& path, const LoopState& state) const {
  Checkpoint c;
  state.Save(&c);
  c.PutModule("generator.", *avatar_.generator);
  c.PutModule("discriminator.", *discriminator_);
  adam_g_.Save("adam_g.", &c);
  adam_d_.Save("adam_d.", &c);
  c.Put("ada", torch::tensor(ada_.State(), torch::kFloat64));
  c.Put("w_average", avatar_.w_average);
  c.Put("frame_codes", frame_codes_);
  c.Put("generator_state", gen_.get_state());
  c.Put("collapse_run", int64_t(watch_.run()));
  return c.Save(path);
}

Status GanTrainer::LoadCheckpoint(const fs::path& path, StatsLog* stats) {
  Checkpoint c;
  HF_RETURN_IF_ERROR(Checkpoint::Load(path, &c));
  const Status damaged = Status::DataError(path.string() + " is not this training's checkpoint; delete it to start over");
  int64_t collapse_run = 0;
  torch::Tensor generator_state, ada;
  if (!state_.Load(c) || !c.Get("generator_state", &generator_state) || !c.Get("ada", &ada) ||
      !c.Get("collapse_run", &collapse_run) || !c.Get("w_average", &avatar_.w_average))
    return damaged;
  if (!c.GetModule("generator.", avatar_.generator.get()) || !c.GetModule("discriminator.", discriminator_.get()))
    return damaged;
  if (!adam_g_.Load("adam_g.", c) || !adam_d_.Load("adam_d.", c)) return damaged;
  ada_.Restore(std::vector<double>(ada.data_ptr<double>(), ada.data_ptr<double>() + ada.numel()));
  watch_.set_run(int(collapse_run));
  {
    torch::NoGradGuard no_grad;
    torch::Tensor codes;
    if (!c.Get("frame_codes", &codes) || !codes.sizes().equals(frame_codes_.sizes())) return damaged;
    frame_codes_.copy_(codes);
  }
  avatar_.w_average = avatar_.w_average.to(device_);
  gen_.set_state(generator_state);
  HF_LOG(Info) << "train: resuming from the checkpoint at step " << state_.step;
  return stats->Truncate(state_.stats_lines);
}

Status GanTrainer::ImportGenerator(const fs::path& dir) {
  GanAvatar trained;
  HF_RETURN_IF_ERROR(LoadGanAvatar(dir, device_, &trained).WithContext("train: --generator-from"));
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadJson(dir / "config.json", &config));
  if (nlohmann::json(arch_) != config.at("architecture") || trained.out_width != data_.width ||
      trained.out_height != data_.height)
    return Status::InvalidArgument("train: --generator-from " + dir.string() + ": its generator (" +
                                   config.at("architecture").dump() + " at " + std::to_string(trained.out_width) + "x" +
                                   std::to_string(trained.out_height) + ") is not the one these options make (" +
                                   nlohmann::json(arch_).dump() + " at " + std::to_string(data_.width) + "x" +
                                   std::to_string(data_.height) + "): was it trained on this workspace's pack?");
  avatar_.generator = trained.generator;
  avatar_.w_average = trained.w_average;
  if (trained.frame_codes.defined()) {
    const bool same = trained.frame_codes.sizes() == frame_codes_.sizes() &&
                      torch::equal(trained.trained_frames.cpu(), TrainingFrames());
    if (same) {
      torch::NoGradGuard no_grad;
      frame_codes_.copy_(trained.frame_codes);
      codes_trained_ = true;
    } else {
      HF_LOG(Warning) << "train: --generator-from " << dir.string() << ": its per-frame latents are for other "
                      << "training frames than these; they are not used";
    }
  }
  if (options_.mapping_latents == "frames" && !codes_trained_)
    return Status::InvalidArgument("train: --mapping-latents frames: the GAN of " + dir.string() +
                                   " kept no latents for this workspace's training frames (a model written before "
                                   "they were kept, or trained without the reconstruction loss); use "
                                   "--mapping-latents random");
  g_params_ = avatar_.generator->parameters();
  state_.step = config.at("training").value("steps", 0);
  state_.seconds = config.at("training").value("seconds", 0.0);
  HF_LOG(Info) << "train: gan-avatar: the generator of " << dir.string() << " (" << state_.step
               << " GAN steps); training the expression mapping only";
  return Status::Ok();
}

Status GanTrainer::Train(const fs::path& out_dir, const fs::path& checkpoint, StatsLog* stats, Progress* progress) {
  if (!options_.generator_from.empty()) return Status::Ok();  // the GAN was trained elsewhere
  out_dir_ = out_dir;
  checkpoint_ = checkpoint;
  HF_RETURN_IF_ERROR(RunLoop(TrainLoopOptions(options_, "train: gan-avatar", options_.steps), this, &state_, stats,
                             progress));
  progress->Finish(std::to_string(state_.step) + " steps");
  // The reconstruction loss fits each training frame's latent, in the
  // warm-up and wherever it is kept beside the adversarial loss.
  codes_trained_ = state_.step > 0 && (options_.reconstruction_steps > 0 || options_.recon_weight > 0);
  // The GAN is done: a kill during the expression mapping resumes here.
  state_.stats_lines = stats->size();
  return SaveCheckpoint(checkpoint, state_);
}

torch::Tensor GanTrainer::TrainingFrames() const {
  std::vector<int64_t> frames;
  for (const AvatarView& v : data_.train) frames.push_back(v.frame);
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  return torch::tensor(frames, torch::kLong);
}

torch::Tensor GanTrainer::MappingCodes(at::Generator& random) const {
  if (options_.mapping_latents != "frames") return torch::Tensor();
  const torch::Tensor trained = frame_codes_.detach().cpu().index_select(0, TrainingFrames());
  const int64_t count = trained.size(0), samples = options_.mapping_samples;
  // Each training frame's latent once (evenly chosen where the samples are
  // fewer), then blends of two frames' latents (expressions between them).
  std::vector<torch::Tensor> rows;
  const int64_t once = std::min(count, samples);
  for (int64_t k = 0; k < once; ++k) rows.push_back(trained[k * count / once]);
  for (int64_t k = count; k < samples; ++k) {
    const int64_t a = torch::randint(count, {1}, random).item<int64_t>();
    const int64_t b = torch::randint(count, {1}, random).item<int64_t>();
    const double t = torch::rand({1}, random).item<double>();
    rows.push_back(torch::lerp(trained[a], trained[b], t));
  }
  HF_LOG(Info) << "train: gan-avatar: the expression mapping's " << samples << " renders come from the warm-up's "
               << "latents of " << once << " of the " << count << " training frames"
               << (samples > count ? ", then blends of two" : "");
  return torch::stack(rows);
}

// The expression mapping's steps: expressions of a batch of the GAN's
// renders to their latents (or, with --mapping-loss image, to the renders).
class GanTrainer::MappingLoop : public LoopTrainer {
 public:
  MappingLoop(GanTrainer& trainer, const torch::Tensor& expressions, const torch::Tensor& w,
              const torch::Tensor& images, at::Generator& random, Adam* adam)
      : t_(trainer), expressions_(expressions), w_(w), images_(images), random_(random), adam_(adam) {}

  void Step(int step, RunningStats* stats) override {
    const int64_t count = expressions_.size(0), batch = std::min<int64_t>(t_.options_.batch, count);
    const torch::Tensor index = torch::randint(count, {batch}, random_, torch::kLong).to(t_.device_);
    const torch::Tensor w = t_.avatar_.mapping->forward(expressions_.index_select(0, index));
    torch::Tensor loss;
    if (t_.options_.mapping_loss == "latent") {
      loss = (w - w_.index_select(0, index)).pow(2).mean();
    } else {
      const SplatCamera camera = t_.RenderCamera(t_.FrontalView());
      const torch::Tensor render = t_.avatar_.generator
                                       ->Render(w, std::vector<SplatCamera>(size_t(batch), camera), t_.data_.width,
                                                t_.data_.height, kBackground, nullptr)
                                       .image;
      loss = (render - images_.index_select(0, index)).abs().mean();
    }
    loss.backward();
    adam_->Step();
    adam_->ZeroGrad();
    t_.mapping_loss_ = loss.item<double>();
    stats->Add("mapping_loss", t_.mapping_loss_);
  }
  std::string DivergenceAdvice() const override { return "try --mapping-loss latent"; }
  bool Evaluate(int step, nlohmann::json* line) override {
    const ViewScores s = MeanScores(t_.Evaluate({}, 5));
    (*line)["test_psnr_masked"] = s.psnr_masked;
    (*line)["test_ssim_masked"] = s.ssim_masked;
    HF_LOG(Info) << "train: expression mapping step " << step << ", held-out PSNR " << s.psnr_masked
                 << " dB over the head (every 5th view)";
    return true;
  }

 private:
  GanTrainer& t_;
  torch::Tensor expressions_, w_, images_;
  at::Generator& random_;
  Adam* adam_;
};

Status GanTrainer::TrainMapping(const ImageTracker& track_images, StatsLog* stats, Progress* progress) {
  if (options_.mapping_steps == 0) return Status::Ok();
  if (!track_images) {
    HF_LOG(Info) << "train: gan-avatar: no expression mapping in this build (its tracker needs the full one); the "
                    "model draws every frame with the mean latent until headforge train --generator-from adds it";
    return Status::Ok();
  }
  if (options_.mapping_latents == "frames" && !codes_trained_)  // TrainOptions::Check and ImportGenerator refuse it first
    return Status::Internal("train: --mapping-latents frames without the training frames' latents");
  const auto start = std::chrono::steady_clock::now();
  for (torch::Tensor& p : g_params_) p.requires_grad_(false);  // the generator is frozen
  const SplatCamera camera = RenderCamera(FrontalView());
  // Its own random stream: the same renders whether the GAN was trained here
  // or imported (--generator-from).
  at::Generator random = at::detail::createCPUGenerator(uint64_t(options_.seed) + 13);
  const int64_t samples = options_.mapping_samples;
  const torch::Tensor codes = MappingCodes(random);
  std::vector<torch::Tensor> ws, renders;
  progress->Start("train: gan-avatar renders for the expression mapping", samples);
  {
    torch::NoGradGuard no_grad;
    for (int64_t first = 0; first < samples; first += kRenderBatch) {
      const int64_t n = std::min<int64_t>(kRenderBatch, samples - first);
      const torch::Tensor z =
          codes.defined() ? codes.narrow(0, first, n) : torch::randn({n, arch_.z_dim}, random);
      ws.push_back(avatar_.generator->Map(z.to(device_)));
      renders.push_back(RenderLatents(ws.back(), camera));
      progress->Advance(n);
      if (InterruptRequested()) {
        progress->Finish("interrupted");
        return Status::Interrupted("train: stopped while rendering the expression mapping's samples; the GAN is "
                                   "kept: run the same command again to go on from it");
      }
    }
  }
  progress->Finish(std::to_string(samples) + " renders");
  HF_RETURN_IF_ERROR(track_images(torch::cat(renders), {camera}, progress, &samples_));
  samples_.w = torch::cat(ws).cpu().index_select(0, samples_.index);
  const int64_t expressions = samples_.expressions.size(1);
  torch::manual_seed(uint64_t(options_.seed) + 11);
  avatar_.mapping = ExpressionMapping(expressions, arch_.w_dim);
  avatar_.mapping->to(device_);
  std::vector<torch::Tensor> params = avatar_.mapping->parameters();
  Adam adam;
  for (torch::Tensor& t : params) adam.Add(&t, 1e-3, false);
  const torch::Tensor e_all = samples_.expressions.to(device_), w_all = samples_.w.to(device_),
                      images = samples_.images.to(device_);
  MappingLoop mapping(*this, e_all, w_all, images, random, &adam);
  LoopOptions loop = TrainLoopOptions(options_, "train: gan-avatar expression mapping", options_.mapping_steps);
  loop.step_key = "mapping_step";
  loop.tags = {{"mapping_loss_kind", options_.mapping_loss}};
  loop.checkpoint_every = 0;  // a few minutes at most: an interrupt keeps the GAN and starts the mapping over
  loop.resume_hint = "the GAN is kept: run the same command again to train the mapping from it";
  loop.what = "the expression mapping";
  loop.clock_offset = state_.seconds + SecondsSince(start);
  LoopState state;
  HF_RETURN_IF_ERROR(RunLoop(loop, &mapping, &state, stats, progress));
  progress->Finish(std::to_string(state.step) + " steps");
  state_.seconds += SecondsSince(start);
  return Status::Ok();
}

Status GanTrainer::CheckMappedExpressions(const ImageTracker& track_images, Progress* progress) {
  if (!avatar_.mapping || !track_images) return Status::Ok();
  torch::NoGradGuard no_grad;
  const int64_t expressions = samples_.expressions.size(1);
  // The frames of the camera the mapping learnt from, at most as many as its
  // own renders, evenly through the capture.
  const AvatarView& frontal = FrontalView();
  std::map<int, const AvatarView*> by_frame;
  for (const std::vector<AvatarView>* list : {&data_.train, &data_.test})
    for (const AvatarView& v : *list)
      if (v.camera == frontal.camera && !v.unreliable) by_frame.emplace(v.frame, &v);
  std::vector<const AvatarView*> all, chosen;
  for (const auto& [frame, v] : by_frame) all.push_back(v);
  const size_t count = std::min(all.size(), size_t(std::max(options_.mapping_samples, 2)));
  for (size_t k = 0; k < count; ++k) chosen.push_back(all[k * all.size() / count]);
  if (chosen.size() < 2) return Status::Ok();
  std::vector<torch::Tensor> rows, frames;
  std::vector<SplatCamera> cameras;
  for (const AvatarView* v : chosen) {
    rows.push_back(v->condition.narrow(0, 0, expressions).to(torch::kFloat32));
    frames.push_back(v->image * v->mask + kBackground * (1 - v->mask));
    cameras.push_back(RenderCamera(*v));
  }
  const torch::Tensor driving = torch::stack(rows);
  const int64_t n = driving.size(0);
  // The mapping's renders from its camera, the mean latent's last.
  const torch::Tensor w =
      torch::cat({avatar_.mapping->forward(driving.to(device_)), avatar_.w_average.unsqueeze(0).to(device_)}, 0);
  const SplatCamera camera = RenderCamera(frontal);
  // A measurement: a reading that fails is said and the model kept (only a
  // stop request stops the stage).
  Status status = Status::Ok();
  auto failed = [&](Status read) {
    if (read.ok()) return false;
    if (read.code() == Status::Code::kInterrupted) status = read;
    else
      HF_LOG(Warning) << "train: gan-avatar: could not read back the mapping's renders or the frames ("
                      << read.message() << "); eval.json has no expression_agreement";
    return true;
  };
  RenderExpressions rendered, seen;
  if (failed(track_images(RenderLatents(w, camera), {camera}, progress, &rendered))) return status;
  // The frames themselves, at the same size over the same background, each
  // from its own camera: what the tracker can read back at this size.
  if (failed(track_images(torch::stack(frames), cameras, progress, &seen))) return status;
  // Rows both readings fitted (where_seen: each frame's row in `seen`, or -1).
  torch::Tensor where_seen = torch::full({n + 1}, -1, torch::kLong);
  where_seen.index_put_({seen.index}, torch::arange(seen.index.size(0)));
  const torch::Tensor both = (rendered.index < n) & (where_seen.index_select(0, rendered.index) >= 0);
  if (!(rendered.index == n).any().item<bool>() || both.sum().item<int64_t>() < 2) {
    HF_LOG(Warning) << "train: gan-avatar: too few of the mapping's renders tracked to say whether they show their "
                       "expressions";
    return Status::Ok();
  }
  const torch::Tensor kept = rendered.index.index({both});
  const torch::Tensor baseline = rendered.expressions.index({rendered.index == n}).squeeze(0);
  const torch::Tensor truth = driving.index_select(0, kept);
  const int all_shapes = int(expressions);
  const ExpressionAgreement a =
      CompareExpressions(truth, rendered.expressions.index({both}), baseline, data_.expression_names, all_shapes);
  const ExpressionAgreement f =
      CompareExpressions(truth, seen.expressions.index_select(0, where_seen.index_select(0, kept)), baseline,
                         data_.expression_names, all_shapes);
  // The blendshapes the frames themselves read back (correlation 0.5 or
  // more: the reading sees them at this size), the most varying first.
  nlohmann::json shapes = nlohmann::json::array();
  std::string line;
  double readable_correlation = 0, readable_frames_correlation = 0;
  int readable = 0;
  // How much each blendshape varies over the mapping's own renders (read
  // back): what it could learn.
  const torch::Tensor sample_spread = samples_.expressions.to(torch::kFloat64).std(0, /*unbiased=*/false);
  for (size_t k = 0; k < a.blendshapes.size(); ++k) {
    const ExpressionAgreement::Blendshape &b = a.blendshapes[k], &g = f.blendshapes[k];
    if (g.correlation < kReadableCorrelation) continue;
    readable_correlation += b.correlation;
    readable_frames_correlation += g.correlation;
    if (++readable > 5) continue;
    shapes.push_back({{"name", b.name}, {"driving_std", b.driving_std}, {"error", b.error},
                      {"correlation", b.correlation}, {"mean_latent_error", b.baseline_error},
                      {"frames_error", g.error}, {"frames_correlation", g.correlation},
                      {"samples_std", sample_spread[b.column].item<double>()}});
    char text[128];
    std::snprintf(text, sizeof(text), "%s%s r = %.2f (frames %.2f)", line.empty() ? "" : ", ", b.name.c_str(),
                  b.correlation, g.correlation);
    line += text;
  }
  expression_check_ = {
      {"what", "frames of " + frontal.camera + " (reliably tracked; at most --mapping-samples, evenly spread) "
               "driving the mapping with their tracked expressions, rendered from the mapping's camera and read "
               "back by the landmark model and tracker, beside one render of the mean latent and the frames "
               "themselves at the model's resolution read back the same way"},
      {"frames", a.frames},
      {"of", n},
      {"error", a.error},
      {"mean_latent_error", a.baseline_error},
      {"frames_error", f.error},
      {"readable_blendshapes", readable},
      {"readable_mean_correlation", readable > 0 ? readable_correlation / readable : 0.0},
      {"readable_frames_mean_correlation", readable > 0 ? readable_frames_correlation / readable : 0.0},
      {"renders_flagged", rendered.flagged},
      {"renders_median_residual_px", rendered.median_residual_px},
      {"frames_flagged", seen.flagged},
      {"frames_median_residual_px", seen.median_residual_px},
      {"blendshapes", shapes}};
  HF_LOG(Info) << "train: gan-avatar: the mapping's renders of " << a.frames << " frames read back within " << a.error
               << " of their expressions (mean absolute weight; the mean latent " << a.baseline_error
               << ", the frames themselves at this size " << f.error << "); of the " << readable
               << " blendshapes the frames read back, the most varying: " << (line.empty() ? "none" : line);
  return Status::Ok();
}

Status GanTrainer::Finish(const fs::path& out_dir, TrainSummary* summary) {
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir / "held_out"));
  const std::vector<ViewScores> scores = Evaluate(out_dir / "held_out", 1);
  const ViewScores mean = MeanScores(scores);
  // The same frames with the mean latent (what the mapping adds), and every
  // tenth training view driven the same way (what the held-out frames lose).
  const ViewScores average = MeanScores(Evaluate({}, 1, /*mean_latent=*/true));
  const ViewScores fitted = MeanScores(Evaluate({}, 10, false, /*training_views=*/true));
  nlohmann::json views = nlohmann::json::array();
  std::map<std::string, std::vector<ViewScores>> by_camera;
  for (const ViewScores& s : scores) {
    views.push_back(ScoresJson(s));
    by_camera[s.camera].push_back(s);
  }
  nlohmann::json cameras = nlohmann::json::object();
  for (const auto& [name, list] : by_camera) {
    const ViewScores m = MeanScores(list);
    cameras[name] = {{"views", list.size()}, {"psnr_masked", m.psnr_masked}, {"ssim_masked", m.ssim_masked}};
  }
  nlohmann::json eval = {
      {"held_out_frames", data_.HeldOutText()},
      {"background", kBackground},
      {"latent", avatar_.mapping ? "the expression mapping (" + options_.mapping_loss +
                                 " loss) of each frame's tracked expression"
                          : std::string("the running mean of w (no expression mapping)")},
      {"mean", ScoresJson(mean, false)},
      {"by_camera", cameras},
      {"mean_latent", {{"psnr_masked", average.psnr_masked}, {"ssim_masked", average.ssim_masked}}},
      {"training_views", {{"psnr_masked", fitted.psnr_masked}, {"ssim_masked", fitted.ssim_masked}}},
      {"mapping", {{"renders", samples_.rendered}, {"tracked", samples_.w.defined() ? samples_.w.size(0) : 0},
                   {"flagged", samples_.flagged}, {"median_residual_px", samples_.median_residual_px},
                   {"loss", options_.mapping_loss}, {"latents", options_.mapping_latents},
                   {"last_loss", mapping_loss_}}},
      {"views", views}};
  if (!expression_check_.is_null()) eval["expression_agreement"] = expression_check_;
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "eval.json", eval, 1));
  // The model: the generator's weights and the mean latent; config.json its architecture.
  Checkpoint model;
  model.PutModule("generator.", *avatar_.generator);
  model.Put("w_average", avatar_.w_average);
  if (avatar_.mapping) model.PutModule("mapping.", *avatar_.mapping);
  if (codes_trained_) {
    model.Put("frame_codes", frame_codes_.detach().cpu());
    model.Put("trained_frames", TrainingFrames());
  }
  HF_RETURN_IF_ERROR(model.Save(out_dir / "model.pt"));
  const nlohmann::json config = {
      {"model", "gan-avatar"},
      {"version", 1},
      {"architecture", arch_},
      {"expression_mapping", {{"expressions", data_.expression_names}, {"hidden", 256}, {"layers", 2},
                              {"loss", options_.mapping_loss}, {"latents", options_.mapping_latents},
                              {"trained", bool(avatar_.mapping)}}},
      {"render_size", {render_w_, render_h_}},
      {"output_size", {data_.width, data_.height}},
      {"background", kBackground},
      {"training", {{"steps", state_.step}, {"batch", options_.batch}, {"seconds", state_.seconds},
                    {"seed", options_.seed}, {"preset", options_.preset}, {"holdout", options_.holdout},
                    {"holdout_order", options_.holdout_order}, {"holdout_cameras", options_.holdout_cameras},
                    {"mask", options_.MaskFor("gan-avatar")}, {"mask_hair", options_.mask_hair},
                    {"mask_skin", options_.mask_skin},
                    {"generator_from", options_.generator_from}}},
      {"options", ToJson(options_)}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "config.json", config, 1));
  summary->steps = state_.step;
  summary->seconds = state_.seconds;
  SetSummaryScores(mean, int(scores.size()), fitted, summary);
  return Status::Ok();
}

}  // namespace

void GanRenderSize(const TrainOptions& options, const AvatarDataset& data, int* width, int* height) {
  const double factor = double(options.render_resolution) / std::max(data.width, data.height);
  *width = std::max(1, int(std::lround(data.width * factor)));
  *height = std::max(1, int(std::lround(data.height * factor)));
}

GanAvatarOptions GanArchitecture(const TrainOptions& options, const AvatarDataset& data) {
  GanAvatarOptions arch;
  arch.z_dim = options.latent_dim;
  arch.plane_resolution = options.triplane_resolution;
  arch.feature_channels = options.feature_channels;
  arch.coarse_samples = options.coarse_samples;
  arch.fine_samples = options.fine_samples;
  arch.super_resolution_doublings =
      int(std::lround(std::log2(double(options.resolution) / double(options.render_resolution))));
  const torch::Tensor v = data.identity_vertices.to(torch::kFloat64);
  const torch::Tensor lo = std::get<0>(v.min(0)), hi = std::get<0>(v.max(0));
  for (int a = 0; a < 3; ++a) {
    arch.box.min[size_t(a)] = lo[a].item<double>() - kBoxPadding;
    arch.box.max[size_t(a)] = hi[a].item<double>() + kBoxPadding;
  }
  return arch;
}

Status TrainGanAvatar(const TrainOptions& options, const AvatarDataset& data, const ImageTracker& track_images,
                      const fs::path& out_dir, Progress* progress, TrainSummary* summary) {
  torch::Device device = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseDevice("train", options.device, &device));
  StatsLog log;
  HF_RETURN_IF_ERROR(OpenTrainStats(out_dir, &log));
  StatsLog* stats = &log;
  *summary = TrainSummary();
  const fs::path checkpoint = out_dir / "checkpoint.pt";
  GanTrainer trainer(options, data, device);
  HF_RETURN_IF_ERROR(trainer.Start(checkpoint, stats));
  const int resumed_from = trainer.step();  // 0 unless a checkpoint was found
  std::error_code ec;
  if (!options.generator_from.empty() && !fs::exists(checkpoint, ec)) {
    HF_RETURN_IF_ERROR(trainer.ImportGenerator(options.generator_from));
    // Its GAN's lines first, so that stats.jsonl tells the whole training.
    std::string text;
    if (stats->size() == 0 && ReadFileToString(fs::path(options.generator_from) / "stats.jsonl", &text).ok()) {
      std::istringstream lines(text);
      for (std::string line; std::getline(lines, line);)
        if (!line.empty() && line.find("\"mapping_step\"") == std::string::npos) stats->Append(line);
    }
  }
  HF_RETURN_IF_ERROR(trainer.Train(out_dir, checkpoint, stats, progress));
  HF_RETURN_IF_ERROR(trainer.TrainMapping(track_images, stats, progress));
  HF_RETURN_IF_ERROR(trainer.CheckMappedExpressions(track_images, progress));
  HF_RETURN_IF_ERROR(trainer.Finish(out_dir, summary));
  summary->resumed_from = resumed_from;
  summary->outputs = {"model.pt", "config.json", "stats.jsonl", "eval.json", "held_out"};
  if (fs::exists(out_dir / "previews", ec)) summary->outputs.push_back("previews");
  fs::remove(checkpoint, ec);
  return Status::Ok();
}

}  // namespace headforge
