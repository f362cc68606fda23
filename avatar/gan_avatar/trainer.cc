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
#include "avatar/gan_avatar/gan_trainer.h"
#include "avatar/model_table.h"
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
namespace gan_training {

namespace F = torch::nn::functional;

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
  if (step == gan_options_.reconstruction_steps + 1 && gan_options_.reconstruction_steps > 0)
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
  const int since = step - gan_options_.reconstruction_steps;
  const int ramp_steps = gan_options_.adversarial_ramp;
  const double ramp = ramp_steps > 0 ? std::min(1.0, double(since) / ramp_steps) : 1.0;
  torch::Tensor total = ramp * loss_g;
  if (gan_options_.recon_weight > 0) total = total + gan_options_.recon_weight * ReconstructionLoss(stats);
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
    const auto start = std::chrono::steady_clock::now();
    const torch::Tensor render = avatar_.Draw(mean_latent ? torch::Tensor() : view.condition, view.view);
    const double ms = 1000 * SecondsSince(start);
    ViewScores s = ScoreRender(render, view.image, view.mask, background);
    s.render_ms = ms;
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
  if (gan_options_.mapping_latents == "frames" && !codes_trained_)
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
  if (!gan_options_.generator_from.empty()) return Status::Ok();  // the GAN was trained elsewhere
  out_dir_ = out_dir;
  checkpoint_ = checkpoint;
  HF_RETURN_IF_ERROR(RunLoop(TrainLoopOptions(options_.loop, "train: gan-avatar", options_.loop.steps), this, &state_,
                             stats, progress));
  progress->Finish(std::to_string(state_.step) + " steps");
  // The reconstruction loss fits each training frame's latent, in the
  // warm-up and wherever it is kept beside the adversarial loss.
  codes_trained_ = state_.step > 0 && (gan_options_.reconstruction_steps > 0 || gan_options_.recon_weight > 0);
  // The GAN is done: a kill during the expression mapping resumes here.
  state_.stats_lines = stats->size();
  return SaveCheckpoint(checkpoint, state_);
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
      {"latent", avatar_.mapping ? "the expression mapping (" + gan_options_.mapping_loss +
                                 " loss) of each frame's tracked expression"
                          : std::string("the running mean of w (no expression mapping)")},
      {"mean", ScoresJson(mean, false)},
      {"by_camera", cameras},
      {"mean_latent", {{"psnr_masked", average.psnr_masked}, {"ssim_masked", average.ssim_masked}}},
      {"training_views", {{"psnr_masked", fitted.psnr_masked}, {"ssim_masked", fitted.ssim_masked}}},
      // Drawing one held-out view at the output size, its image back on the
      // CPU, on the training device (the first view, warming up, left out).
      {"render_ms", MeanRenderMs(scores)},
      {"device", options_.device},
      {"mapping", {{"renders", samples_.rendered}, {"tracked", samples_.w.defined() ? samples_.w.size(0) : 0},
                   {"flagged", samples_.flagged}, {"median_residual_px", samples_.median_residual_px},
                   {"loss", gan_options_.mapping_loss}, {"latents", gan_options_.mapping_latents},
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
  // The options it trained with (the masks resolved, as render and export read them), once.
  TrainOptions recorded = options_;
  recorded.data = options_.DataFor(kGanAvatar);
  const nlohmann::json config = {
      {"model", kGanAvatar.name},
      {"version", 1},
      {"architecture", arch_},
      {"expression_mapping", {{"expressions", data_.expression_names}, {"hidden", 256}, {"layers", 2},
                              {"trained", bool(avatar_.mapping)}}},
      {"render_size", {render_w_, render_h_}},
      {"output_size", {data_.width, data_.height}},
      {"background", kBackground},
      {"training", {{"steps", state_.step}, {"seconds", state_.seconds}}},
      {"options", ToJson(recorded)}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "config.json", config, 1));
  summary->steps = state_.step;
  summary->seconds = state_.seconds;
  SetSummaryScores(mean, int(scores.size()), fitted, summary);
  return Status::Ok();
}

}  // namespace gan_training

using gan_training::GanTrainer;
using gan_training::kBoxPadding;

void GanRenderSize(const TrainOptions& options, const AvatarDataset& data, int* width, int* height) {
  const double factor = double(options.gan_avatar.render_resolution) / std::max(data.width, data.height);
  *width = std::max(1, int(std::lround(data.width * factor)));
  *height = std::max(1, int(std::lround(data.height * factor)));
}

GanAvatarOptions GanArchitecture(const TrainOptions& options, const AvatarDataset& data) {
  GanAvatarOptions arch;
  arch.z_dim = options.latent_dim;
  arch.plane_resolution = options.triplane_resolution;
  arch.feature_channels = options.feature_channels;
  arch.coarse_samples = options.gan_avatar.coarse_samples;
  arch.fine_samples = options.gan_avatar.fine_samples;
  arch.super_resolution_doublings =
      int(std::lround(std::log2(double(options.data.resolution) / double(options.gan_avatar.render_resolution))));
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
  const std::string& generator_from = options.gan_avatar.generator_from;
  if (!generator_from.empty() && !fs::exists(checkpoint, ec)) {
    HF_RETURN_IF_ERROR(trainer.ImportGenerator(generator_from));
    // Its GAN's lines first, so that stats.jsonl tells the whole training.
    std::string text;
    if (stats->size() == 0 && ReadFileToString(fs::path(generator_from) / "stats.jsonl", &text).ok()) {
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
