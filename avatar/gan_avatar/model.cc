#include "avatar/gan_avatar/model.h"

#include <torch/torch.h>

#include <cmath>

#include "avatar/nn/functional.h"

namespace headforge {

namespace F = torch::nn::functional;

GanGeneratorImpl::GanGeneratorImpl(const GanAvatarOptions& options) : options_(options) {
  TORCH_CHECK(options.feature_channels >= 3, "gan-avatar: at least the three colour channels");
  TORCH_CHECK(options.super_resolution_doublings >= 0, "gan-avatar: negative super-resolution doublings");
  nn::TriplaneGeneratorOptions planes;
  planes.latent_dim = options.z_dim;
  planes.w_dim = options.w_dim;
  planes.channels = options.synthesis_channels;
  planes.resolution = options.plane_resolution;
  planes.plane_channels = options.plane_channels;
  planes.mapping_layers = options.mapping_layers;
  planes_ = register_module("planes", nn::TriplaneGenerator(planes));
  decoder_ = register_module(
      "decoder", nn::Mlp(std::vector<int64_t>{options.plane_channels, options.decoder_hidden, 1 + options.feature_channels}));
  super_resolution_ = register_module("super_resolution", torch::nn::ModuleList());
  int64_t in = options.feature_channels;
  for (int i = 0; i < options.super_resolution_doublings; ++i) {
    super_resolution_->push_back(nn::ModulatedConv2d(in, options.synthesis_channels, 3, options.w_dim));
    super_resolution_->push_back(
        nn::ModulatedConv2d(options.synthesis_channels, options.synthesis_channels, 3, options.w_dim));
    in = options.synthesis_channels;
  }
  to_rgb_ = register_module("to_rgb", nn::ModulatedConv2d(in, 3, 1, options.w_dim, /*demodulate=*/false));
  // The super-resolution adds to the upsampled volume render: start it small.
  torch::NoGradGuard no_grad;
  to_rgb_->weight.mul_(0.1);
}

void GanGeneratorImpl::Field(const torch::Tensor& planes, const torch::Tensor& points, torch::Tensor* density,
                             torch::Tensor* features) {
  const int64_t c = options_.plane_channels, fc = options_.feature_channels;
  std::vector<int64_t> shape = points.sizes().vec();
  shape.pop_back();  // the points' leading dimensions: [N] or [B, N]
  // EG3D's aggregation: the mean of the three planes' features.
  const torch::Tensor sampled =
      nn::SampleTriplane(planes, options_.box.Normalise(points)).reshape({-1, 3, c}).mean(1);
  const torch::Tensor out = decoder_->forward(sampled);  // [N', 1 + F]
  *density = (F::softplus(out.select(1, 0) - 1) * options_.density_scale).view(shape);
  // Colour and features squashed to a little over [0, 1], as EG3D's decoder does.
  shape.push_back(fc);
  *features = (torch::sigmoid(out.narrow(1, 1, fc)) * (1 + 2 * 0.001) - 0.001).view(shape);
}

GanRender GanGeneratorImpl::Render(const torch::Tensor& w, const std::vector<SplatCamera>& cameras, int64_t out_width,
                                   int64_t out_height, double background, at::Generator* jitter) {
  const int64_t batch = w.size(0);
  TORCH_CHECK(int64_t(cameras.size()) == batch && batch > 0, "gan-avatar: one camera per latent");
  const int64_t h = cameras[0].height, wd = cameras[0].width;
  for (const SplatCamera& camera : cameras)
    TORCH_CHECK(camera.width == wd && camera.height == h, "gan-avatar: the batch's cameras differ in size");
  const torch::Tensor planes = Planes(w);  // [B, 3, C, R, R]
  const int64_t fc = options_.feature_channels;
  // Every camera's rays, sample by sample: [B * h * w, 3].
  std::vector<torch::Tensor> origins, directions;
  for (const SplatCamera& camera : cameras) {
    const volume::Rays r = volume::GenerateRays(camera, w.device());
    origins.push_back(r.origins);
    directions.push_back(r.directions);
  }
  volume::Rays rays{torch::cat(origins).to(w.dtype()), torch::cat(directions).to(w.dtype())};
  const volume::Segments segments = volume::IntersectBox(rays, options_.box);
  const int64_t per_camera = h * wd;
  auto evaluate = [&](const torch::Tensor& depths, torch::Tensor* sigma, torch::Tensor* feat) {
    const int64_t s = depths.size(1);
    const torch::Tensor points = rays.origins.unsqueeze(1) + rays.directions.unsqueeze(1) * depths.unsqueeze(2);
    Field(planes, points.view({batch, per_camera * s, 3}), sigma, feat);
    *sigma = sigma->view({batch * per_camera, s});
    *feat = feat->view({batch * per_camera, s, fc});
  };
  const torch::Tensor coarse = volume::StratifiedDepths(segments, options_.coarse_samples, jitter);
  torch::Tensor sigma0, feat0;
  evaluate(coarse, &sigma0, &feat0);
  volume::Composite composite = volume::CompositeSamples(sigma0, feat0, coarse, segments);
  if (options_.fine_samples > 0) {
    const torch::Tensor fine = volume::ImportanceDepths(segments, coarse, composite.weights, options_.fine_samples, jitter);
    torch::Tensor sigma1, feat1;
    evaluate(fine, &sigma1, &feat1);
    const volume::Samples merged = volume::MergeSamples({coarse, {sigma0, feat0}}, {fine, {sigma1, feat1}});
    composite = volume::CompositeSamples(merged.values[0], merged.values[1], merged.depths, segments);
  }
  GanRender out;
  out.features = composite.features.view({batch, h, wd, fc}).permute({0, 3, 1, 2});  // [B, F, h, w]
  out.opacity = composite.opacity.view({batch, 1, h, wd});
  out.raw = out.features.narrow(1, 0, 3) + (1 - out.opacity) * background;
  // Super-resolution: the raw colour upsampled, plus what the modulated
  // convolutions make of the features (with the background) at each doubling.
  torch::Tensor x = torch::cat({out.raw, out.features.narrow(1, 3, fc - 3)}, 1);
  const int doublings = options_.super_resolution_doublings;
  for (int i = 0; i < doublings; ++i) {
    const bool last = i + 1 == doublings;
    const int64_t th = last ? out_height : h << (i + 1), tw = last ? out_width : wd << (i + 1);
    x = nn::ResizeBilinear(x, th, tw);
    x = nn::LeakyRelu(super_resolution_[size_t(2 * i)]->as<nn::ModulatedConv2d>()->forward(x, w));
    x = nn::LeakyRelu(super_resolution_[size_t(2 * i + 1)]->as<nn::ModulatedConv2d>()->forward(x, w));
  }
  if (x.size(2) != out_height || x.size(3) != out_width) x = nn::ResizeBilinear(x, out_height, out_width);
  out.image = nn::ResizeBilinear(out.raw, out_height, out_width) + to_rgb_->forward(x, w);
  return out;
}

// The architecture's scalar fields, each written and read under its own name.
#define HF_GAN_ARCHITECTURE_FIELDS(X)                                                                         \
  X(z_dim) X(w_dim) X(mapping_layers) X(synthesis_channels) X(plane_resolution) X(plane_channels)            \
  X(decoder_hidden) X(feature_channels) X(coarse_samples) X(fine_samples) X(super_resolution_doublings)       \
  X(density_scale)

void to_json(nlohmann::json& json, const GanAvatarOptions& options) {
#define HF_WRITE(field) json[#field] = options.field;
  HF_GAN_ARCHITECTURE_FIELDS(HF_WRITE)
#undef HF_WRITE
  json["box_min"] = options.box.min;
  json["box_max"] = options.box.max;
}

void from_json(const nlohmann::json& json, GanAvatarOptions& options) {
#define HF_READ(field) json.at(#field).get_to(options.field);
  HF_GAN_ARCHITECTURE_FIELDS(HF_READ)
#undef HF_READ
  json.at("box_min").get_to(options.box.min);
  json.at("box_max").get_to(options.box.max);
}

#undef HF_GAN_ARCHITECTURE_FIELDS

torch::Tensor CameraCondition(const SplatCamera& camera) {
  std::vector<double> c(camera.cam_from_world.begin(), camera.cam_from_world.end());
  c.push_back(camera.fx / camera.width);
  c.push_back(camera.fy / camera.height);
  c.push_back((camera.cx + 0.5) / camera.width);
  c.push_back((camera.cy + 0.5) / camera.height);
  return torch::tensor(c, torch::kFloat32);
}

}  // namespace headforge
