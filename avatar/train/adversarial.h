// The discriminator's half of a GAN step, as the gan-avatar GAN and stage 3's
// two GANs (the prior, the fusion) take it: the non-saturating logistic loss
// on a batch of real and of generated images, both augmented (ADA), with
// lazy R1 on the reals every r1_every steps (StyleGAN2: its term scaled by
// r1_every), one Adam step, and ADA's controller fed the real logits.
#pragma once

#include <torch/types.h>

#include "avatar/nn/augment.h"
#include "avatar/nn/discriminator.h"
#include "avatar/train/adam.h"

namespace headforge {

struct DiscriminatorBatch {
  torch::Tensor real, fake;          // [B, C, H, W]; fake is detached here
  torch::Tensor real_condition, fake_condition;  // [B, c], or undefined (unconditional)
  int64_t colour_channels = 3;       // Augment()'s colour channels
  double augment_p = 0;              // ADA's p (0: no augmentation)
};

struct DiscriminatorUpdate {
  double loss = 0;                   // the logistic loss plus R1's term
  bool has_r1 = false;               // R1 was taken this step
  double r1 = 0;                     // the mean squared gradient norm on the reals
  double real_accuracy = 0, fake_accuracy = 0;  // reals called real, fakes called fake
};

struct R1Options {
  double gamma = 1;
  int every = 16;
};

// Leaves `d`'s gradients zeroed; the random augmentations come from `generator`.
DiscriminatorUpdate UpdateDiscriminator(nn::DiscriminatorImpl& d, Adam& adam, nn::AdaController& ada,
                                        const DiscriminatorBatch& batch, const R1Options& r1, int step,
                                        at::Generator& generator);

}  // namespace headforge
