// The gan-avatar model's options on the command line and in config files
// (train.*), with their short flags; the full build's alone.
#include "avatar/gan_avatar/options.h"
#include "core/options.h"

namespace headforge {

void AddGanAvatarOptions(OptionSet* o, GanAvatarTrainOptions* g) {
  o->Add("train.render_resolution", &g->render_resolution,
         "gan-avatar: the volume render's longer side; --train-size / this must be a power of two.",
         "render-resolution");
  o->Add("train.reconstruction_steps", &g->reconstruction_steps,
         "gan-avatar: the first steps reconstruct the training frames (L1, a latent per frame) before the "
         "adversarial training: a personal prior in place of pretrained EG3D weights (0: none).",
         "reconstruction-steps");
  o->Add("train.recon_weight", &g->recon_weight,
         "gan-avatar: weight of the reconstruction loss kept beside the adversarial one after the warm-up (0: "
         "adversarial alone).",
         "recon-weight");
  o->Add("train.adversarial_ramp", &g->adversarial_ramp,
         "gan-avatar: steps after the warm-up over which the generator's adversarial loss rises from 0 to 1.",
         "adversarial-ramp");
  o->Add("train.coarse_samples", &g->coarse_samples, "gan-avatar: stratified samples per ray.", "samples");
  o->Add("train.fine_samples", &g->fine_samples, "gan-avatar: importance samples per ray (0: none).",
         "fine-samples");
  o->Add("train.mapping_samples", &g->mapping_samples,
         "gan-avatar: latents rendered frontally and tracked to train the expression mapping.", "mapping-samples");
  o->Add("train.mapping_steps", &g->mapping_steps, "gan-avatar: steps of the expression mapping (0: none).",
         "mapping-steps");
  o->Add("train.mapping_loss", &g->mapping_loss,
         "gan-avatar: image (the render of the mapped w against the sampled render, generator frozen) or latent "
         "(the mapped w against the sampled w).",
         "mapping-loss");
  o->Add("train.mapping_latents", &g->mapping_latents,
         "gan-avatar: the latents the mapping's renders come from: random (z ~ N(0, I), the paper's) or frames (the "
         "reconstruction warm-up's latent of each training frame, then blends of two frames').",
         "mapping-latents");
  o->Add("train.landmark_model", &g->landmark_model,
         "gan-avatar: dlib's 68-point landmark model, which reads the renders' landmarks (default: Debian's "
         "libdlib-data).",
         "landmark-model", OptionSet::Effect::kRuntime);
  o->Add("train.generator_from", &g->generator_from,
         "gan-avatar: the folder of a GAN trained already (headforge-train's --out for this workspace's pack, e.g. on "
         "a GPU machine): its generator is taken, only the expression mapping trains here, and the options that "
         "shape the model and its views are the ones recorded there.",
         "generator-from");
}

}  // namespace headforge
