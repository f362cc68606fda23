// What `headforge export` takes from a trained avatar, for callers that do
// not use LibTorch: one frame's Gaussians as plain arrays, and the networks as
// weights.safetensors + config.json.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {
class Progress;
}

namespace headforge {

// Gaussians in the avatar's head frame (metres, +y up, the face toward +z).
struct AvatarSplats {
  std::vector<float> means;      // [N, 3]
  std::vector<float> rotations;  // [N, 4] unit quaternions w, x, y, z
  std::vector<float> scales;     // [N, 3] standard deviations along the rotated axes, metres
  std::vector<float> opacities;  // [N] in [0, 1]
  std::vector<float> colours;    // [N, 3] RGB in [0, 1] (sRGB, as trained)
  size_t size() const { return opacities.size(); }
};

// The pose export calls canonical: every expression weight 0, frame 0's head pose.
constexpr int kNeutralFrame = -1;

// The Gaussians the avatar trained in `model_dir` shows at `frame` of
// `workspace` (its tracked expression and head pose), or at kNeutralFrame.
Status PoseAvatarSplats(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                        int frame, AvatarSplats* splats);
// The same for each of `frames` in turn (the model loaded once), handed to
// `each`; the first error, of a frame or of `each`, ends it.
Status PoseAvatarFrames(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                        const std::vector<int>& frames,
                        const std::function<Status(int frame, const AvatarSplats& splats)>& each);

// The avatar's Gaussians and networks as `out_dir`/weights.safetensors and
// `out_dir`/config.json: the training config plus what a reader needs to
// drive it (the face model's identity, the condition's layout, the tensors'
// names). LoadAvatar and `headforge render --model` read the folder back.
Status ExportAvatarWeights(const fs::path& workspace, const fs::path& model_dir, const fs::path& out_dir,
                           std::vector<std::string>* files);
// The same for a gan-avatar model: the generator, the mean latent and the
// expression mapping, with the expressions' names and the face model's
// identity; `headforge render --model` reads the folder back.
Status ExportGanWeights(const fs::path& workspace, const fs::path& model_dir, const fs::path& out_dir,
                        std::vector<std::string>* files);

// Linear Gaussian blendshapes distilled from the gaussian-style avatar in
// `model_dir` (avatar/gaussian_style/blendshapes.h), written to `out_dir`
// as blendshapes.bin (little-endian float32: opacities [N], the neutral
// attributes [N, 13], then each expression's offsets [N, 13]) and
// blendshapes.json (its layout, the expressions' names, the scores);
// `*scores` the held-out frames drawn by the networks and by the
// blendshapes (RGB splats, frame 0's latent, each view's tracked expression).
struct BlendshapeScores {
  int gaussians = 0, expressions = 0, samples = 0, held_out_views = 0;
  double psnr_network = 0, psnr_blendshapes = 0;  // over the head, mean of the held-out views
  double psnr_fitted = 0;  // the blendshapes as fitted to the networks, before a refinement
  double ms_network = 0, ms_blendshapes = 0;      // posing and drawing one view
  double fit_seconds = 0;
  // Pruning before the refinement (none: gaussians_fitted == gaussians).
  int gaussians_fitted = 0;
  double psnr_pruned = 0, prune_light_kept = 1, prune_seconds = 0;
  std::vector<int64_t> pruned_kept;  // the kept Gaussians' indices in the avatar's (gaussians.ply's) order
  // The refinement against the training frames (none: refine_steps 0).
  int refine_steps = 0, refine_kept_step = 0, validation_views = 0;
  double validation_psnr_before = 0, validation_psnr_after = 0, refine_seconds = 0;
  std::vector<std::pair<int, double>> validation_curve;  // (step, PSNR over the head) at each evaluation
};
// The refinement through the rasterizer after the fit (blendshapes.h).
struct BlendshapeExportOptions {
  double prune = 0;  // the fraction of the Gaussians removed before the refinement (the least light first)
  int refine_steps = 0;
  double refine_minutes = 0;
};
// The blendshapes as plain arrays: the Gaussians with every weight 0 and
// each expression's offsets of the 13 attributes (position 3, rotation w, x,
// y, z 4, log-scale 3, RGB 3), expression-major [K, N, 13].
struct AvatarBlendshapes {
  AvatarSplats neutral;
  std::vector<std::string> names;
  std::vector<float> offsets;
  std::vector<float> neutral_attributes;  // [N, 13]: the neutral state before normalising, exp and clamping
};
Status ExportAvatarBlendshapes(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                               const BlendshapeExportOptions& options, const fs::path& out_dir,
                               BlendshapeScores* scores, std::vector<std::string>* files, AvatarBlendshapes* arrays,
                               Progress* progress);

}  // namespace headforge
