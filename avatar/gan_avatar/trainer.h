// Training the gan-avatar model's appearance GAN on an AvatarDataset: the
// generator (model.h) against a camera-conditioned discriminator that sees
// the super-resolved image and the raw volume render together (dual
// discrimination), non-saturating logistic losses, lazy R1 on the real
// images, adaptive augmentation; checkpoints, stats.jsonl and previews; then
// the expression mapping (expression_mapping.h).
#pragma once

#include <torch/types.h>

#include <functional>
#include <vector>

#include "avatar/avatar_train.h"
#include "avatar/gan_avatar/expression_mapping.h"
#include "avatar/gan_avatar/model.h"
#include "avatar/splat/splat_camera.h"
#include "avatar/train/dataset.h"

namespace headforge {

// The generator's architecture for `options` and `data`: the box round the
// tracked identity's mesh (padded for hair), the render and output sizes.
GanAvatarOptions GanArchitecture(const TrainOptions& options, const AvatarDataset& data);

// The volume render's size for `data`'s frames at `options`' render resolution.
void GanRenderSize(const TrainOptions& options, const AvatarDataset& data, int* width, int* height);

// What the expression mapping learns from: the expression of each of
// `images` ([M, 3, H, W] in [0, 1], the GAN's renders or frames drawn like
// them, seen from `cameras`, one or one each) estimated
// (render_expressions.h, the full build's landmark model and tracker).
using ImageTracker = std::function<Status(const torch::Tensor& images, const std::vector<SplatCamera>& cameras,
                                          Progress* progress, RenderExpressions* out)>;

// Trains into `out_dir` (checkpoint.pt between attempts; a run that finds
// one continues from it); writes model.pt, config.json (with every option,
// for --generator-from), eval.json, held_out/ and previews/. Then, with
// `track_images`, trains the expression mapping, and scores the held-out
// frames driven by their tracked expressions; without it (headforge-train,
// the LibTorch-only program) the model has no mapping and draws every frame
// with the mean latent. With options.generator_from (a folder this function
// wrote for the same views and architecture) the GAN is that folder's and
// only the mapping trains. Opens out_dir's stats.jsonl and lists the
// summary's outputs: the train stage's run, and a run from a pack.
Status TrainGanAvatar(const TrainOptions& options, const AvatarDataset& data, const ImageTracker& track_images,
                      const fs::path& out_dir, Progress* progress, TrainSummary* summary);

}  // namespace headforge
