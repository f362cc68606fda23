// The gan-avatar model's generator (GAN-Avatar, Kabadayi et al. 2024, on
// EG3D's architecture, Chan et al. 2022): a mapping network z -> w, a
// StyleGAN2-like synthesis of three feature planes from w, a small decoder
// MLP from a point's plane features to a density and a feature whose first
// three channels are colour, volume rendering of that field inside the
// head's box (avatar/volume), and a super-resolution network from the
// rendered feature image to the output image. The camera is an input of the
// rendering only: the mapping never sees it.
#pragma once

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/pimpl.h>

#include <vector>

#include <nlohmann/json.hpp>

#include "avatar/nn/mlp.h"
#include "avatar/nn/modulated_conv.h"
#include "avatar/nn/triplane.h"
#include "avatar/splat/splat_camera.h"
#include "avatar/volume/volume_render.h"

namespace headforge {

struct GanAvatarOptions {
  int64_t z_dim = 64, w_dim = 128;
  int mapping_layers = 2;
  int64_t synthesis_channels = 64;  // of the plane synthesis and the super-resolution
  int64_t plane_resolution = 64;    // a power of two >= 8
  int64_t plane_channels = 32;
  int64_t decoder_hidden = 64;
  int64_t feature_channels = 32;    // rendered per pixel; the first three are colour
  int64_t coarse_samples = 24, fine_samples = 24;  // per ray
  int super_resolution_doublings = 1;  // output side = render side x 2^this
  volume::Box box;                  // the head's box in the head frame, metres
  // Density = softplus(raw - 1) * density_scale (per metre): about how many
  // optical depths a raw value near 1 gives across one metre.
  double density_scale = 30;
};

// The architecture as config.json holds it, and back (nlohmann::json's
// conversions; reading throws nlohmann::json::exception on a missing field).
void to_json(nlohmann::json& json, const GanAvatarOptions& options);
void from_json(const nlohmann::json& json, GanAvatarOptions& options);

struct GanRender {
  torch::Tensor image;     // [B, 3, H, W] the super-resolved image
  torch::Tensor raw;       // [B, 3, h, w] the volume render's colour over the background
  torch::Tensor features;  // [B, F, h, w] the volume render's features (colour first, no background)
  torch::Tensor opacity;   // [B, 1, h, w]
};

class GanGeneratorImpl : public torch::nn::Module {
 public:
  explicit GanGeneratorImpl(const GanAvatarOptions& options);

  torch::Tensor Map(const torch::Tensor& z) { return planes_->Map(z); }  // [B, z_dim] -> [B, w_dim]
  torch::Tensor Planes(const torch::Tensor& w) { return planes_->Synthesize(w); }  // -> [B, 3, C, R, R]

  // The field at `points` [N, 3] (head frame) on planes [3, C, R, R]:
  // densities [N] and features [N, F]; batched, points [B, N, 3] on planes
  // [B, 3, C, R, R]: densities [B, N] and features [B, N, F].
  void Field(const torch::Tensor& planes, const torch::Tensor& points, torch::Tensor* density,
             torch::Tensor* features);

  // Renders sample b of w [B, w_dim] from cameras[b] (at the volume render's
  // resolution, the same size for every b) over `background` (grey level of
  // the colour channels), then super-resolves to out_width x out_height.
  // `jitter` (may be null) jitters the depths; without it they are the bins'
  // centres. The batch's rays go through the volume render together.
  GanRender Render(const torch::Tensor& w, const std::vector<SplatCamera>& cameras, int64_t out_width,
                   int64_t out_height, double background, at::Generator* jitter);

  const GanAvatarOptions& options() const { return options_; }

 private:
  GanAvatarOptions options_;
  nn::TriplaneGenerator planes_{nullptr};
  nn::Mlp decoder_{nullptr};
  torch::nn::ModuleList super_resolution_;  // two modulated 3x3 convolutions per doubling
  nn::ModulatedConv2d to_rgb_{nullptr};
};
TORCH_MODULE(GanGenerator);

// The camera as the discriminator's condition: cam_from_head's 12 entries,
// then fx / width, fy / height and the principal point over the size -> [16]
// (resolution-free: the same camera at any size gives the same condition).
torch::Tensor CameraCondition(const SplatCamera& camera);

}  // namespace headforge
