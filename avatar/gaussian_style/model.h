// The gaussian-style avatar's networks and Gaussians (GaussianStyle, §3.1):
// canonical Gaussians carrying a feature each; a temporal triplane generator
// (a learned latent per frame -> three feature planes) on which each
// Gaussian looks up its canonical position; two transformer blocks in which
// those features attend to tokens of the frame's tracked expression and head
// pose; and a deform MLP predicting each Gaussian's change of feature,
// position, rotation and scale. Optionally (mesh riding, beyond the paper)
// the Gaussians are bound to the tracked mesh's triangles and the network
// predicts changes in their triangles' frames.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/modules/linear.h>
#include <torch/nn/pimpl.h>

#include "avatar/gaussian_style/binding.h"
#include "avatar/nn/mlp.h"
#include "avatar/nn/triplane.h"
#include "avatar/train/densify.h"

namespace headforge {

struct GaussianStyleOptions {
  int64_t feature_channels = 32;  // carried by each Gaussian; the first three are RGB (logits)
  nn::TriplaneGeneratorOptions triplane;
  int64_t token_dim = 32;         // the transformer's width
  int64_t heads = 4;
  int blocks = 2;
  int64_t ffn_hidden = 64;        // the gated feed-forward's hidden width
  int64_t deform_hidden = 64;
  int64_t expressions = 53;       // the condition: expressions, then 9 numbers of head pose
  bool mesh_riding = false;
  double box_half_size = 0.2;     // metres: the planes span this cube round the head frame's origin
};

// One frame's Gaussians, ready for the rasterizer.
struct PosedGaussians {
  torch::Tensor means, quats, log_scales;  // [N, 3], [N, 4], [N, 3]
  torch::Tensor opacities;                 // [N]
  torch::Tensor features;                  // [N, F]: RGB in [0, 1], then the other channels raw
};

// `posed` moved rigidly by `correction` [6]: an axis-angle rotation
// (radians) about the head frame's origin, then a translation (metres);
// differentiable in both. A training view's head-pose correction.
PosedGaussians CorrectPose(const PosedGaussians& posed, const torch::Tensor& correction);

// The Gaussians' parameters (rows; densification edits them): positions,
// rotations and scales canonical, or local to their triangle with mesh
// riding; `colour_logits` holds the F-channel features.
struct AvatarGaussians {
  GaussianParams params;
  torch::Tensor binding;  // [N] int64 triangle, with mesh riding
};

class GaussianStyleImpl : public torch::nn::Module {
 public:
  GaussianStyleImpl(const GaussianStyleOptions& options, int64_t frames);
  const GaussianStyleOptions& options() const { return options_; }

  // The Gaussians as the frame with `condition` [E + 9] sees them. `latent`
  // picks the frame latent (inference uses frame 0's); `mesh` is the frame's
  // tracked mesh and `neutral` the mesh without expression (mesh riding
  // only); without `deform` (training stage 1) the network leaves the
  // Gaussians where they are.
  PosedGaussians Pose(const AvatarGaussians& gaussians, const torch::Tensor& condition, int64_t latent,
                      const TriangleFrames* mesh, const TriangleFrames* neutral, bool deform);

  // Per-Gaussian plane features [N, 3 * plane_channels] at canonical positions [N, 3].
  torch::Tensor PlaneFeatures(const torch::Tensor& canonical, int64_t latent);
  // The condition's tokens [E + 2, D]: one per expression (its weight times a
  // learned vector, plus a learned offset), one for the head pose, one constant.
  torch::Tensor Tokens(const torch::Tensor& condition);
  // [N, F + 10]: d feature, d position, d rotation (quaternion), d log-scale.
  torch::Tensor Deform(const torch::Tensor& plane_features, const torch::Tensor& condition);

  // The parameters trained in stage 1 (generator, latents, decoder) and the
  // ones stage 2 adds (the transformer and the deformer).
  std::vector<torch::Tensor> CanonicalParameters();
  std::vector<torch::Tensor> DeformationParameters();

 private:
  GaussianStyleOptions options_;
  nn::TriplaneGenerator generator_{nullptr};
  torch::Tensor latents_;  // [frames, latent_dim]
  torch::nn::Linear decoder_{nullptr}, in_proj_{nullptr};
  torch::Tensor expression_embed_, expression_bias_, constant_token_;  // [E, D], [E, D], [1, D]
  nn::Mlp pose_embed_{nullptr};
  torch::nn::ModuleList blocks_;
  nn::Mlp deform_{nullptr};
};
TORCH_MODULE(GaussianStyle);

}  // namespace headforge
