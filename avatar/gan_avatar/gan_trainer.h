// The gan-avatar model's trainer, shared by its two files: trainer.cc (the
// GAN's loop, evaluation, checkpoints and model file) and
// mapping_trainer.cc (the expression mapping and its check). Private to
// avatar/gan_avatar/.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <string>
#include <vector>

#include "avatar/gan_avatar/avatar_io.h"
#include "avatar/gan_avatar/trainer.h"
#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"
#include "avatar/nn/functional.h"
#include "avatar/train/adam.h"
#include "avatar/train/gan_watch.h"
#include "avatar/train/loop.h"
#include "avatar/train/view_scores.h"

namespace headforge::gan_training {

// The background of the real images (outside their masks) and of the
// renders (where the volume is transparent); also the evaluation's.
inline constexpr double kBackground = 0.5;
inline constexpr int64_t kRenderBatch = 8;  // renders drawn at once outside training
// A blendshape the frames read back with this correlation to their tracked
// weights is one the landmark reading sees at the model's resolution.
inline constexpr double kReadableCorrelation = 0.5;
// Padding of the head's box round the tracked mesh, metres (hair).
inline constexpr double kBoxPadding = 0.04;
// The running mean of w follows the batches' with this weight.
inline constexpr double kWAverageRate = 0.01;
// Adam's step for the warm-up's per-frame latents.
inline constexpr double kCodeLearningRate = 1e-2;

class GanTrainer : public LoopTrainer {
 public:
  GanTrainer(const TrainOptions& options, const AvatarDataset& data, torch::Device device)
      : options_(options), data_(data), device_(device), gen_(at::detail::createCPUGenerator(options.seed)),
        adam_g_(0.0, 0.99), adam_d_(0.0, 0.99), ada_(options.ada_target), watch_(options.collapse_steps) {}

  Status Start(const fs::path& checkpoint, StatsLog* stats);
  // The generator of a finished training (its options' generator_from) in
  // place of this one's; Train then trains no GAN.
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
  bool reconstructing(int step) const { return step <= gan_options_.reconstruction_steps; }
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
  const GanAvatarTrainOptions& gan_options_ = options_.gan_avatar;  // the model's own part of options_
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

}  // namespace headforge::gan_training
