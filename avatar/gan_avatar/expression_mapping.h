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

#include <string>
#include <vector>

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
  torch::Tensor index;        // [M] which render (of those made) each row is
  int rendered = 0;           // renders made
  int flagged = 0;            // of those kept, how many the tracker flagged low-confidence
  double median_residual_px = 0;  // the tracker's, at the landmark image's scale
};

// Whether renders driven by expressions show them: `driving` [N, E] the
// expressions that chose each render's latent, `tracked` [N, E] what the
// tracker reads back from those renders, `baseline` [E] what it reads from
// one render that ignores the expression (the mean latent). Distances are
// mean absolute weights; per blendshape (the `top` that vary most over
// `driving`), the Pearson correlation of tracked with driving (0 where
// either is constant).
struct ExpressionAgreement {
  struct Blendshape {
    std::string name;
    int64_t column = 0;  // its column in the expression tensors
    double driving_std = 0;
    double error = 0;           // mean |tracked - driving|
    double baseline_error = 0;  // mean |baseline - driving|
    double correlation = 0;
  };
  int frames = 0;
  double error = 0;
  double baseline_error = 0;
  std::vector<Blendshape> blendshapes;  // most varying first
};
ExpressionAgreement CompareExpressions(const torch::Tensor& driving, const torch::Tensor& tracked,
                                       const torch::Tensor& baseline, const std::vector<std::string>& names,
                                       int top = 5);

}  // namespace headforge
