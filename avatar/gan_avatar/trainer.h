// Training the gan-avatar model's appearance GAN on an AvatarDataset: the
// generator (model.h) against a camera-conditioned discriminator that sees
// the super-resolved image and the raw volume render together (dual
// discrimination), non-saturating logistic losses, lazy R1 on the real
// images, adaptive augmentation; checkpoints, stats.jsonl and previews; then
// the expression mapping (expression_mapping.h).
#pragma once

#include <torch/types.h>

#include "avatar/avatar_train.h"
#include "avatar/gan_avatar/model.h"
#include "avatar/train/dataset.h"
#include "core/stats_log.h"

namespace headforge {

// The generator's architecture for `options` and `data`: the box round the
// tracked identity's mesh (padded for hair), the render and output sizes.
GanAvatarOptions GanArchitecture(const TrainOptions& options, const AvatarDataset& data);

// The volume render's size for `data`'s frames at `options`' render resolution.
void GanRenderSize(const TrainOptions& options, const AvatarDataset& data, int* width, int* height);

// Trains into `out_dir` (checkpoint.pt between attempts; a run that finds
// one continues from it); writes model.pt, config.json, eval.json,
// held_out/ and previews/.
// Then samples renders, tracks them and trains the expression mapping, and
// scores the held-out frames driven by their tracked expressions.
Status TrainGanAvatar(const TrainOptions& options, const fs::path& workspace, const AvatarDataset& data,
                      const FaceModel& model, const fs::path& out_dir, StatsLog* stats, Progress* progress,
                      TrainSummary* summary);

}  // namespace headforge
