// Linear Gaussian blendshapes distilled from a trained gaussian-style avatar:
// every Gaussian's position, rotation, scale and colour in the head frame as
// a neutral value plus one offset per expression blendshape, so that any
// renderer (a game engine's morph targets) poses it with a weighted sum
// instead of the avatar's networks. The offsets are fitted by least squares
// to what the networks give over the training frames' tracked expressions
// and expressions sampled round them; the head's rigid motion goes on top,
// as for the networks' output. Opacity does not change with the expression.
#pragma once

#include <torch/torch.h>

#include "avatar/gaussian_style/trainer.h"

namespace headforge {

// The attributes of one Gaussian, in this order, in a blendshape's rows.
inline constexpr int64_t kBlendshapeAttributes = 13;  // position 3, rotation (w, x, y, z) 4, log-scale 3, RGB 3

struct GaussianBlendshapes {
  torch::Tensor neutral;    // [N, 13] at every expression weight 0
  torch::Tensor offsets;    // [K, N, 13] per unit of each expression's weight
  torch::Tensor opacities;  // [N] in [0, 1]
  torch::Tensor pose_condition;  // [9] the head-pose input the networks were evaluated at
  std::vector<std::string> names;  // the K expressions (the face model's, ARKit's names)
};

// The least-squares linear map from `inputs` [S, K] to `outputs` [S, M]
// (float64): [K + 1, M], its first row the intercept; `ridge` >= 0 damps
// the K slopes (not the intercept) where the samples leave them loose.
torch::Tensor FitLinearModel(const torch::Tensor& inputs, const torch::Tensor& outputs, double ridge);

// What the distillation samples: each training view's expression, and
// `perturbed_per_view` more round it (Gaussian, `spread` in weight, clamped
// to [0, 1]), all at the training views' mean head-pose input.
struct DistilOptions {
  int perturbed_per_view = 2;
  double spread = 0.15;
  double ridge = 1e-4;
  uint64_t seed = 1;
};

// The blendshapes of `avatar` (frame 0's latent, as inference takes it).
GaussianBlendshapes DistilBlendshapes(GaussianStyleAvatar& avatar, const AvatarDataset& data,
                                      const DistilOptions& options);

// The Gaussians at `expression` [K], ready for the rasterizer (features: RGB).
PosedGaussians PoseBlendshapes(const GaussianBlendshapes& shapes, const torch::Tensor& expression);

// The blendshapes refined through the rasterizer against the training frames
// (L1 and SSIM over the head, a random background each step, as training
// has it): every attribute of the neutral state, the offsets and the
// opacities, by Adam at a tenth of training's first step sizes decaying to
// a hundredth. Every n-th training view (`validation`) is set aside and
// scored every `eval_every` steps; the state it scores highest is kept,
// the fit to the networks when no step beats it.
struct BlendshapeRefineOptions {
  int steps = 0;            // 0: none
  double max_minutes = 0;   // > 0: stop after this much time
  double lr_scale = 0.1;    // of training's first step sizes
  double offset_lr_ratio = 0.5;  // the offsets' step sizes against the neutral state's
  double ssim_weight = 0.2;
  double validation = 0.1;  // the fraction of training views set aside
  int eval_every = 50;
  uint64_t seed = 1;
  Status Check() const;
};
struct BlendshapeRefineReport {
  int steps = 0;       // steps run
  int kept_step = 0;   // the step whose state was kept (0: the fit to the networks)
  int validation_views = 0;
  double validation_psnr_before = 0, validation_psnr_after = 0;  // over the head, the views set aside
  double seconds = 0;
  std::vector<std::pair<int, double>> curve;  // (step, the views set aside's PSNR) at each evaluation
};
Status RefineBlendshapes(const AvatarDataset& data, const BlendshapeRefineOptions& options,
                         GaussianBlendshapes* shapes, BlendshapeRefineReport* report, Progress* progress);

// The Gaussians that give the least light removed, before a refinement lets
// the rest take their place: each one's light is its alpha times the
// transmittance before it, summed over the pixels it reaches in every
// training view (at the view's expression and pose), and the `fraction`
// with the least is dropped. Fewer Gaussians draw faster; what it costs is
// measured by the held-out frames (docs/benchmarks/export.md).
struct BlendshapePruneReport {
  int before = 0, after = 0;
  double light_kept = 1;  // the kept Gaussians' share of the light summed over the views
  double seconds = 0;
  std::vector<int64_t> kept;  // the kept Gaussians' indices before pruning, ascending (empty: none pruned)
};
Status PruneBlendshapes(const AvatarDataset& data, double fraction, GaussianBlendshapes* shapes,
                        BlendshapePruneReport* report);

// Whether `dir` holds exported blendshapes (blendshapes.json).
bool IsBlendshapeFolder(const fs::path& dir);
// Reads what ExportAvatarBlendshapes wrote into `dir`; `*data` the dataset
// options of the avatar they came from (its frames held out as it held them).
Status ReadGaussianBlendshapes(const fs::path& dir, GaussianBlendshapes* shapes, DatasetOptions* data);

}  // namespace headforge
