// The gan-avatar model's expression mapping (GAN-Avatar §3.2): an MLP from a
// tracked expression to the generator's w, trained on the generator's own
// renders. Latents are sampled, rendered from a frontal training camera, and
// HeadForge's landmark model and tracker estimate each render's expression
// (render_expressions.h; the paper runs Deep3DFace there); the MLP then learns, with the generator
// frozen, to reproduce each render from its estimated expression (the
// photometric loss), or to reproduce its w (the latent loss, the ablation).
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/pimpl.h>

#include "avatar/gan_avatar/model.h"
#include "avatar/nn/mlp.h"

namespace headforge {

class ExpressionMappingImpl : public torch::nn::Module {
 public:
  ExpressionMappingImpl(int64_t expressions, int64_t w_dim, int64_t hidden = 256);
  torch::Tensor forward(const torch::Tensor& expressions) { return mlp_->forward(expressions); }  // [B, E] -> [B, w_dim]

 private:
  nn::Mlp mlp_{nullptr};
};
TORCH_MODULE(ExpressionMapping);

struct RenderExpressions {
  torch::Tensor w;            // [M, w_dim] of the renders the tracker fitted
  torch::Tensor expressions;  // [M, E] their estimated expressions
  torch::Tensor images;       // [M, 3, H, W] the renders
  int rendered = 0;           // renders made
  int flagged = 0;            // of those kept, how many the tracker flagged low-confidence
  double median_residual_px = 0;  // the tracker's, at the landmark image's scale
};

}  // namespace headforge
