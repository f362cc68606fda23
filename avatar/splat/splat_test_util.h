// Scenes and checks shared by the rasterizer tests. Scenes are made and
// checked on the CPU; the kernels under test run on KernelDevice(): the CPU,
// or the GPU in avatar_cuda_test (built from the same tests with
// HEADFORGE_SPLAT_TEST_CUDA), where inputs are copied over differentiably
// and outputs copied back.
#pragma once

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <functional>
#include <vector>

#include "avatar/splat/splat_ops.h"
#include "avatar/splat/splat_reference.h"

namespace headforge::splat_test {

// Parameters of a Gaussian scene; every tensor a leaf that requires grad.
struct Scene {
  torch::Tensor means, quats, log_scales, opacities, features, background;
  SplatCamera camera;

  std::vector<torch::Tensor> Inputs() const {
    return {means, quats, log_scales, opacities, features, background};
  }
  Scene To(torch::Dtype dtype) const;
};

inline torch::Device KernelDevice() {
#ifdef HEADFORGE_SPLAT_TEST_CUDA
  return torch::Device(torch::kCUDA, 0);
#else
  return torch::kCPU;
#endif
}

inline const char* kInputNames[] = {"means", "quats", "log_scales", "opacities", "features",
                                    "background"};

// N Gaussians in front of a small camera (width x height, 3 x 3 tiles at the
// default 40 x 36), sized to cover a few to a few tens of pixels.
inline Scene RandomScene(int64_t n, int64_t channels, uint64_t seed, int width = 40,
                         int height = 36) {
  auto gen = at::detail::createCPUGenerator(seed);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  Scene s;
  s.camera.width = width;
  s.camera.height = height;
  s.camera.fx = 40;
  s.camera.fy = 42;
  s.camera.cx = width / 2.0 - 0.3;
  s.camera.cy = height / 2.0 + 0.2;
  // A slightly rotated and shifted camera, so every axis of the transform matters.
  const double c = std::cos(0.1), sn = std::sin(0.1);
  s.camera.cam_from_world = {c, 0, sn, 0.05, 0, 1, 0, -0.02, -sn, 0, c, 0.1};
  auto uniform = [&](std::vector<int64_t> shape, double lo, double hi) {
    return torch::rand(shape, gen, opts) * (hi - lo) + lo;
  };
  const auto z = uniform({n, 1}, 1.5, 3.5);
  const auto xy = uniform({n, 2}, -0.6, 0.6) * z;
  s.means = torch::cat({xy, z}, 1);
  s.quats = torch::randn({n, 4}, gen, opts);
  s.log_scales = uniform({n, 3}, std::log(0.03), std::log(0.2));
  s.opacities = uniform({n}, 0.05, 0.95);
  s.features = uniform({n, channels}, 0.0, 1.0);
  s.background = uniform({channels}, 0.0, 1.0);
  for (auto* t : {&s.means, &s.quats, &s.log_scales, &s.opacities, &s.features, &s.background}) {
    t->requires_grad_(true);
  }
  return s;
}

inline Scene Scene::To(torch::Dtype dtype) const {
  Scene s = *this;
  for (auto* t : {&s.means, &s.quats, &s.log_scales, &s.opacities, &s.features, &s.background}) {
    *t = t->detach().to(dtype).requires_grad_(true);
  }
  return s;
}

struct Rendered {
  torch::Tensor image, alpha, depth;
};

// The scene's tensors on `device`; gradients flow back to the originals.
inline Scene OnDevice(const Scene& s, torch::Device device) {
  Scene d = s;
  for (auto* t : {&d.means, &d.quats, &d.log_scales, &d.opacities, &d.features, &d.background}) {
    *t = t->to(device);
  }
  return d;
}

inline torch::Tensor ToCpu(const torch::Tensor& t) { return t.defined() ? t.cpu() : t; }

inline Rendered RenderOn(torch::Device device, const Scene& scene, bool depth = false) {
  const Scene s = OnDevice(scene, device);
  SplatRenderOptions options;
  options.depth = depth;
  const auto r = RenderGaussians(s.means, s.quats, s.log_scales, s.opacities, s.features,
                                 s.background, s.camera, options);
  return {ToCpu(r.image), ToCpu(r.alpha), ToCpu(r.depth)};
}

inline Rendered RenderKernel(const Scene& s, bool depth = false) {
  return RenderOn(KernelDevice(), s, depth);
}

// ProjectGaussians on KernelDevice(), results on the CPU.
inline ProjectResult ProjectKernel(const Scene& scene, const SplatOptions& options = {}) {
  const Scene s = OnDevice(scene, KernelDevice());
  const ProjectResult p = ProjectGaussians(s.means, s.quats, s.log_scales, s.camera, options);
  return {ToCpu(p.means2d), ToCpu(p.conics), ToCpu(p.depths), ToCpu(p.radii)};
}

// IntersectTiles on KernelDevice(), lists on the CPU.
inline TileIntersections IntersectKernel(const ProjectResult& p, int width, int height) {
  const torch::Device device = KernelDevice();
  TileIntersections t = IntersectTiles(p.means2d.to(device), p.radii.to(device),
                                       p.depths.to(device), width, height);
  t.tile_offsets = t.tile_offsets.cpu();
  t.gaussian_ids = t.gaussian_ids.cpu();
  return t;
}

inline Rendered RenderReference(const Scene& s, bool depth = false) {
  const auto p = splat_reference::Project(s.means, s.quats, s.log_scales, s.camera);
  torch::Tensor feats = s.features, bg = s.background;
  if (depth) {
    feats = torch::cat({feats, p.depths.unsqueeze(1)}, 1);
    bg = torch::cat({bg, torch::zeros({1}, bg.options())});
  }
  const auto r = splat_reference::Rasterize(p.means2d, p.conics, feats, s.opacities, bg, p.radii,
                                            p.depths, s.camera.width, s.camera.height);
  Rendered out{r.image, r.alpha, {}};
  if (depth) {
    const int64_t c = s.features.size(1);
    out.image = r.image.slice(0, 0, c);
    out.depth = torch::where(r.alpha > 0, r.image[c] / r.alpha.clamp_min(1e-10),
                             torch::zeros_like(r.alpha));
  }
  return out;
}

// A scalar loss that weighs every output by fixed random weights.
struct Loss {
  torch::Tensor w_image, w_alpha, w_depth;
  Loss(int64_t channels, int height, int width, uint64_t seed) {
    auto gen = at::detail::createCPUGenerator(seed);
    const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
    w_image = torch::randn({channels, height, width}, gen, opts);
    w_alpha = torch::randn({height, width}, gen, opts);
    w_depth = torch::randn({height, width}, gen, opts);
  }
  torch::Tensor operator()(const Rendered& r) const {
    const auto dt = r.image.scalar_type();
    auto loss = (r.image * w_image.to(dt)).sum() + (r.alpha * w_alpha.to(dt)).sum();
    if (r.depth.defined()) loss = loss + (r.depth * w_depth.to(dt)).sum();
    return loss;
  }
};

// A camera on a horizontal ring of `radius` round the origin, looking at it
// (OpenCV axes: y down, world +y up).
inline SplatCamera RingCamera(double angle, double radius, int side) {
  const double ex = radius * std::sin(angle), ez = -radius * std::cos(angle);
  const double z[3] = {-ex / radius, 0, -ez / radius};  // toward the origin
  const double y[3] = {0, -1, 0};
  const double x[3] = {y[1] * z[2] - y[2] * z[1], y[2] * z[0] - y[0] * z[2],
                       y[0] * z[1] - y[1] * z[0]};
  const double* rows[3] = {x, y, z};
  SplatCamera c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) c.cam_from_world[4 * i + j] = rows[i][j];
    c.cam_from_world[4 * i + 3] = -(rows[i][0] * ex + rows[i][2] * ez);
  }
  c.width = c.height = side;
  c.fx = c.fy = 1.2 * side;
  c.cx = c.cy = side / 2.0 - 0.5;
  return c;
}

inline double MaxAbs(const torch::Tensor& t) {
  return t.numel() == 0 ? 0.0 : t.abs().max().item<double>();
}

inline double MaxAbsDiff(const torch::Tensor& a, const torch::Tensor& b) {
  return a.numel() == 0 ? 0.0 : (a.to(torch::kFloat64) - b.to(torch::kFloat64)).abs().max().item<double>();
}

// Gradients of loss(render(scene)) with respect to every input.
inline std::vector<torch::Tensor> Gradients(const Scene& s, const Loss& loss,
                                            const std::function<Rendered(const Scene&)>& render) {
  const auto inputs = s.Inputs();
  return torch::autograd::grad({loss(render(s))}, inputs, {}, false, false, true);
}

inline bool AllFinite(const torch::Tensor& t) {
  return !t.defined() || t.numel() == 0 || torch::isfinite(t).all().item<bool>();
}

}  // namespace headforge::splat_test
