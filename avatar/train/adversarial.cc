#include "avatar/train/adversarial.h"

#include <torch/torch.h>

namespace headforge {

DiscriminatorUpdate UpdateDiscriminator(nn::DiscriminatorImpl& d, Adam& adam, nn::AdaController& ada,
                                        const DiscriminatorBatch& batch, const R1Options& r1, int step,
                                        at::Generator& generator) {
  namespace F = torch::nn::functional;
  const double p = batch.augment_p;
  const torch::Tensor fake_logits =
      d.forward(nn::Augment(batch.fake.detach(), p, batch.colour_channels, generator), batch.fake_condition);
  DiscriminatorUpdate out;
  out.has_r1 = r1.gamma > 0 && step % r1.every == 0;
  torch::Tensor real_in = nn::Augment(batch.real.detach(), p, batch.colour_channels, generator);
  if (out.has_r1) real_in = real_in.detach().requires_grad_(true);
  const torch::Tensor real_logits = d.forward(real_in, batch.real_condition);
  torch::Tensor loss = F::softplus(fake_logits).mean() + F::softplus(-real_logits).mean();
  if (out.has_r1) {
    const torch::Tensor grad =
        torch::autograd::grad({real_logits.sum()}, {real_in}, {}, /*retain_graph=*/true, /*create_graph=*/true)[0];
    const torch::Tensor penalty = grad.pow(2).sum({1, 2, 3}).mean();
    loss = loss + 0.5 * r1.gamma * r1.every * penalty;
    out.r1 = penalty.item<double>();
  }
  loss.backward();
  adam.Step();
  adam.ZeroGrad();
  ada.Observe(real_logits);
  out.loss = loss.item<double>();
  out.real_accuracy = (real_logits > 0).to(torch::kFloat64).mean().item<double>();
  out.fake_accuracy = (fake_logits < 0).to(torch::kFloat64).mean().item<double>();
  return out;
}

}  // namespace headforge
