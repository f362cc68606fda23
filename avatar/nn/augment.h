// Adaptive discriminator augmentation (Karras et al. 2020, "Training
// Generative Adversarial Networks with Limited Data"): every image the
// discriminator sees, real or generated, is transformed at random with
// probability p per transform, so that a discriminator trained on few
// images cannot memorise them; p follows how sure the discriminator is of
// the real images (r_t = E[sign(D(real))], steered toward a target).
// Geometric transforms are applied identically to every channel of a sample
// (an image and its UV map stay registered); colour transforms only to the
// colour channels, three at a time.
#pragma once

#include <torch/types.h>

#include <vector>

namespace headforge::nn {

struct AugmentOptions {
  double max_translation = 0.125;  // of the image's size, uniform per axis
  double scale_std = 0.2;          // log2 of the isotropic scale, normal
  bool rotate = true;              // uniform over the full circle
  double brightness_std = 0.2;     // added, normal
  double contrast_std = 0.5;       // log2 of the contrast about the mean, normal
};

// x [B, C, H, W]; channels [0, colour_channels) are colour images in groups
// of three. p = 0 returns x itself. Reflection at the borders; the random
// numbers come from `generator`.
torch::Tensor Augment(const torch::Tensor& x, double p, int64_t colour_channels, at::Generator& generator,
                      const AugmentOptions& options = {});

// ADA's controller: after each batch of real logits, Observe(); every
// `interval` batches p moves by sign(r_t - target) * (images seen since) /
// (speed_images), within [0, 1].
class AdaController {
 public:
  AdaController(double target = 0.6, int interval = 4, double speed_images = 5000)
      : target_(target), interval_(interval), speed_images_(speed_images) {}
  void Observe(const torch::Tensor& real_logits);
  double p() const { return p_; }
  double rt() const { return last_rt_; }
  // For checkpoints: p, the running sums and counts, and back.
  std::vector<double> State() const { return {p_, sign_sum_, double(images_), double(batches_), last_rt_}; }
  void Restore(const std::vector<double>& state);

 private:
  double target_;
  int interval_;
  double speed_images_;
  double p_ = 0, sign_sum_ = 0, last_rt_ = 0;
  int64_t images_ = 0;
  int batches_ = 0;
};

}  // namespace headforge::nn
