// The gan-avatar model's expression mapping: renders of the trained GAN
// read back by the landmark model and tracker, a small network from their
// expressions to the latents that drew them, trained in the training loop,
// and the check that the mapping's renders show the expressions that drive
// them.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <map>

#include "avatar/gan_avatar/gan_trainer.h"
#include "avatar/train_loop_options.h"
#include "core/interrupt.h"
#include "core/log.h"

namespace headforge::gan_training {

torch::Tensor GanTrainer::TrainingFrames() const {
  std::vector<int64_t> frames;
  for (const AvatarView& v : data_.train) frames.push_back(v.frame);
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  return torch::tensor(frames, torch::kLong);
}

torch::Tensor GanTrainer::MappingCodes(at::Generator& random) const {
  if (gan_options_.mapping_latents != "frames") return torch::Tensor();
  const torch::Tensor trained = frame_codes_.detach().cpu().index_select(0, TrainingFrames());
  const int64_t count = trained.size(0), samples = gan_options_.mapping_samples;
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
    if (t_.gan_options_.mapping_loss == "latent") {
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
  if (gan_options_.mapping_steps == 0) return Status::Ok();
  if (!track_images) {
    HF_LOG(Info) << "train: gan-avatar: no expression mapping in this build (its tracker needs the full one); the "
                    "model draws every frame with the mean latent until headforge train --generator-from adds it";
    return Status::Ok();
  }
  if (gan_options_.mapping_latents == "frames" && !codes_trained_)  // TrainOptions::Check and ImportGenerator refuse it first
    return Status::Internal("train: --mapping-latents frames without the training frames' latents");
  const auto start = std::chrono::steady_clock::now();
  for (torch::Tensor& p : g_params_) p.requires_grad_(false);  // the generator is frozen
  const SplatCamera camera = RenderCamera(FrontalView());
  // Its own random stream: the same renders whether the GAN was trained here
  // or imported (--generator-from).
  at::Generator random = at::detail::createCPUGenerator(uint64_t(options_.seed) + 13);
  const int64_t samples = gan_options_.mapping_samples;
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
  LoopOptions loop =
      TrainLoopOptions(options_.loop, "train: gan-avatar expression mapping", gan_options_.mapping_steps);
  loop.step_key = "mapping_step";
  loop.tags = {{"mapping_loss_kind", gan_options_.mapping_loss}};
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
  const size_t count = std::min(all.size(), size_t(std::max(gan_options_.mapping_samples, 2)));
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

}  // namespace headforge::gan_training
