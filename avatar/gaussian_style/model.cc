#include "avatar/gaussian_style/model.h"

#include <torch/torch.h>

#include "avatar/nn/attention.h"

namespace headforge {
namespace {

// What one unit of the deformer's output moves: metres in the canonical
// frame, triangle sizes (about 2 mm) when riding the mesh; the rotation and
// the log-scale a tenth each, so the zero-initialised last layer starts gently.
constexpr double kCanonicalStep = 0.01, kRidingStep = 1.0, kRotationStep = 0.1, kScaleStep = 0.1;

}  // namespace

GaussianStyleImpl::GaussianStyleImpl(const GaussianStyleOptions& options, int64_t frames) : options_(options) {
  const int64_t planes = 3 * options.triplane.plane_channels, d = options.token_dim;
  generator_ = register_module("generator", nn::TriplaneGenerator(options.triplane));
  latents_ = register_parameter("latents", torch::randn({std::max<int64_t>(frames, 1), options.triplane.latent_dim}));
  decoder_ = register_module("decoder", torch::nn::Linear(planes, options.feature_channels));
  in_proj_ = register_module("in_proj", torch::nn::Linear(planes, d));
  expression_embed_ = register_parameter("expression_embed", torch::randn({options.expressions, d}) * 0.5);
  expression_bias_ = register_parameter("expression_bias", torch::randn({options.expressions, d}) * 0.1);
  constant_token_ = register_parameter("constant_token", torch::randn({1, d}) * 0.1);
  pose_embed_ = register_module("pose_embed", nn::Mlp(std::vector<int64_t>{9, d, d}));
  blocks_ = register_module("blocks", torch::nn::ModuleList());
  for (int b = 0; b < options.blocks; ++b)
    blocks_->push_back(nn::CrossAttentionBlock(d, options.heads, options.ffn_hidden));
  deform_ = register_module(
      "deform", nn::Mlp(std::vector<int64_t>{d, options.deform_hidden, options.feature_channels + 10}, true));
  torch::NoGradGuard no_grad;
  decoder_->weight.mul_(0.1);  // the Gaussians' own features lead at first
  decoder_->bias.zero_();
}

torch::Tensor GaussianStyleImpl::PlaneFeatures(const torch::Tensor& canonical, int64_t latent) {
  const torch::Tensor planes = generator_->forward(latents_.slice(0, latent, latent + 1))[0];
  return nn::SampleTriplane(planes, canonical / options_.box_half_size);
}

torch::Tensor GaussianStyleImpl::Tokens(const torch::Tensor& condition) {
  const int64_t e = options_.expressions;
  const torch::Tensor weights = condition.slice(0, 0, e).unsqueeze(1);
  const torch::Tensor pose = pose_embed_->forward(condition.slice(0, e, e + 9).unsqueeze(0));
  return torch::cat({weights * expression_embed_ + expression_bias_, pose, constant_token_});
}

torch::Tensor GaussianStyleImpl::Deform(const torch::Tensor& plane_features, const torch::Tensor& condition) {
  const torch::Tensor tokens = Tokens(condition);
  torch::Tensor h = in_proj_->forward(plane_features);
  for (const auto& block : *blocks_) h = block->as<nn::CrossAttentionBlock>()->forward(h, tokens);
  return deform_->forward(h);
}

PosedGaussians GaussianStyleImpl::Pose(const AvatarGaussians& gaussians, const torch::Tensor& condition,
                                       int64_t latent, const TriangleFrames* mesh, const TriangleFrames* neutral,
                                       bool deform) {
  const GaussianParams& p = gaussians.params;
  const int64_t f = options_.feature_channels;
  TORCH_CHECK(!options_.mesh_riding || (mesh && neutral && gaussians.binding.defined()),
              "a mesh-riding avatar needs the frame's mesh, the neutral mesh and its binding");
  // Where each Gaussian sits on the planes: its canonical position, which
  // for riding Gaussians is on the mesh without expression.
  torch::Tensor canonical = p.means;
  if (options_.mesh_riding)
    canonical = ApplyBinding(*neutral, gaussians.binding, p.means, p.quats, p.log_scales).means;
  const torch::Tensor plane = PlaneFeatures(canonical.detach(), latent);
  torch::Tensor features = p.colour_logits + decoder_->forward(plane);
  torch::Tensor means = p.means, quats = p.quats, log_scales = p.log_scales;
  if (deform) {
    const torch::Tensor d = Deform(plane, condition.to(plane.dtype()));
    features = features + d.slice(1, 0, f);
    means = means + d.slice(1, f, f + 3) * (options_.mesh_riding ? kRidingStep : kCanonicalStep);
    quats = quats + d.slice(1, f + 3, f + 7) * kRotationStep;
    log_scales = log_scales + d.slice(1, f + 7, f + 10) * kScaleStep;
  }
  PosedGaussians out;
  if (options_.mesh_riding) {
    const BoundGaussians bound = ApplyBinding(*mesh, gaussians.binding, means, quats, log_scales);
    out.means = bound.means;
    out.quats = bound.quats;
    out.log_scales = bound.log_scales;
  } else {
    out.means = means;
    out.quats = quats;
    out.log_scales = log_scales;
  }
  out.opacities = torch::sigmoid(p.opacity_logits);
  out.features = torch::cat({torch::sigmoid(features.slice(1, 0, 3)), features.slice(1, 3)}, 1);
  return out;
}

std::vector<torch::Tensor> GaussianStyleImpl::CanonicalParameters() {
  std::vector<torch::Tensor> out = generator_->parameters();
  out.push_back(latents_);
  for (const auto& t : decoder_->parameters()) out.push_back(t);
  return out;
}

std::vector<torch::Tensor> GaussianStyleImpl::DeformationParameters() {
  std::vector<torch::Tensor> out = {expression_embed_, expression_bias_, constant_token_};
  for (auto* m : std::initializer_list<torch::nn::Module*>{in_proj_.get(), pose_embed_.get(), blocks_.get(), deform_.get()})
    for (const auto& t : m->parameters()) out.push_back(t);
  return out;
}

PosedGaussians CorrectPose(const PosedGaussians& posed, const torch::Tensor& correction) {
  const torch::Tensor axis_angle = correction.slice(0, 0, 3), shift = correction.slice(0, 3, 6);
  // The norm's gradient at zero is undefined: a tiny offset keeps it finite.
  const torch::Tensor angle = (axis_angle.square().sum() + 1e-12).sqrt();
  const torch::Tensor axis = axis_angle / angle;
  const torch::Tensor half = angle / 2, s = torch::sin(half);
  const torch::Tensor w = torch::cos(half), x = s * axis[0], y = s * axis[1], z = s * axis[2];
  // The rotation matrix of the unit quaternion (w, x, y, z).
  const torch::Tensor rotation = torch::stack({1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                                               2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                                               2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)})
                                   .view({3, 3});
  PosedGaussians out = posed;
  out.means = torch::matmul(posed.means, rotation.t()) + shift;
  // The Hamilton product (w, x, y, z) * q for every Gaussian's rotation q.
  const torch::Tensor q = posed.quats;
  const torch::Tensor qw = q.select(1, 0), qx = q.select(1, 1), qy = q.select(1, 2), qz = q.select(1, 3);
  out.quats = torch::stack({w * qw - x * qx - y * qy - z * qz, w * qx + x * qw + y * qz - z * qy,
                            w * qy - x * qz + y * qw + z * qx, w * qz + x * qy - y * qx + z * qw},
                           1);
  return out;
}

}  // namespace headforge
