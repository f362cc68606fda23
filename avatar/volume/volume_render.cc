#include "avatar/volume/volume_render.h"

#include <torch/torch.h>

#include <limits>

namespace headforge::volume {

Rays GenerateRays(const SplatCamera& camera, torch::Device device) {
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
  const auto& m = camera.cam_from_world;
  const torch::Tensor rotation = torch::tensor({m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]}, f64).view({3, 3});
  const torch::Tensor translation = torch::tensor({m[3], m[7], m[11]}, f64);
  const torch::Tensor centre = -torch::matmul(rotation.t(), translation);  // R^T (-t)
  const torch::Tensor x = torch::arange(camera.width, f64), y = torch::arange(camera.height, f64);
  const std::vector<torch::Tensor> grid = torch::meshgrid({y, x}, "ij");  // [H, W] each
  const torch::Tensor in_camera = torch::stack({(grid[1] - camera.cx) / camera.fx, (grid[0] - camera.cy) / camera.fy,
                                                torch::ones_like(grid[0])},
                                               -1)
                                      .view({-1, 3});
  torch::Tensor directions = torch::matmul(in_camera, rotation);  // rows: R^T d
  directions = directions / directions.norm(2, 1, true);
  const int64_t count = directions.size(0);
  return {centre.view({1, 3}).expand({count, 3}).to(device, torch::kFloat32).contiguous(),
          directions.to(device, torch::kFloat32)};
}

torch::Tensor Box::Normalise(const torch::Tensor& point) const {
  const auto opts = point.options();
  const torch::Tensor lo = torch::tensor({min[0], min[1], min[2]}, opts.dtype(torch::kFloat64)).to(opts);
  const torch::Tensor hi = torch::tensor({max[0], max[1], max[2]}, opts.dtype(torch::kFloat64)).to(opts);
  return (point - lo) / (hi - lo) * 2 - 1;
}

Segments IntersectBox(const Rays& rays, const Box& box) {
  const auto opts = rays.origins.options();
  const torch::Tensor lo = torch::tensor({box.min[0], box.min[1], box.min[2]}, opts.dtype(torch::kFloat64)).to(opts);
  const torch::Tensor hi = torch::tensor({box.max[0], box.max[1], box.max[2]}, opts.dtype(torch::kFloat64)).to(opts);
  const torch::Tensor& o = rays.origins;
  const torch::Tensor& d = rays.directions;
  // Per axis, the depths at which the ray crosses the two planes. An axis the
  // ray runs parallel to bounds nothing when the origin is between its planes
  // and everything otherwise (0 * inf would make a NaN of it).
  const torch::Tensor parallel = d == 0;
  const torch::Tensor safe = torch::where(parallel, torch::ones_like(d), d);
  const torch::Tensor t0 = (lo - o) / safe, t1 = (hi - o) / safe;
  const double inf = std::numeric_limits<double>::infinity();
  const torch::Tensor between = (o >= lo) & (o <= hi);
  const torch::Tensor open_lo = torch::full_like(d, -inf), open_hi = torch::full_like(d, inf);
  const torch::Tensor axis_near =
      torch::where(parallel, torch::where(between, open_lo, open_hi), torch::minimum(t0, t1));
  const torch::Tensor axis_far = torch::where(parallel, torch::where(between, open_hi, open_lo), torch::maximum(t0, t1));
  const torch::Tensor t_near = std::get<0>(axis_near.max(1)).clamp_min(0);
  const torch::Tensor t_far = std::get<0>(axis_far.min(1));
  const torch::Tensor hit = t_far > t_near;
  const torch::Tensor zero = torch::zeros_like(t_near);
  return {torch::where(hit, t_near, zero), torch::where(hit, t_far, zero), hit};
}

torch::Tensor StratifiedDepths(const Segments& segments, int64_t samples, at::Generator* generator) {
  TORCH_CHECK(samples >= 1, "volume: at least one sample per ray");
  const auto opts = segments.t_near.options();
  const int64_t rays = segments.t_near.size(0);
  const torch::Tensor offsets = generator ? torch::rand({rays, samples}, *generator, opts.device(torch::kCPU)).to(opts)
                                          : torch::full({rays, samples}, 0.5, opts);
  const torch::Tensor bins = (torch::arange(samples, opts).view({1, samples}) + offsets) / double(samples);
  const torch::Tensor length = (segments.t_far - segments.t_near).unsqueeze(1);
  return segments.t_near.unsqueeze(1) + length * bins;
}

torch::Tensor IntervalEdges(const torch::Tensor& depths, const Segments& segments) {
  return torch::cat({segments.t_near.unsqueeze(1).to(depths.dtype()), depths,
                     segments.t_far.unsqueeze(1).to(depths.dtype())},
                    1);
}

torch::Tensor IntervalValues(const torch::Tensor& values) {
  const int64_t s = values.size(1);
  const torch::Tensor between = (values.narrow(1, 0, s - 1) + values.narrow(1, 1, s - 1)) * 0.5;
  return torch::cat({values.narrow(1, 0, 1), between, values.narrow(1, s - 1, 1)}, 1);
}

torch::Tensor ImportanceDepths(const Segments& segments, const torch::Tensor& depths, const torch::Tensor& weights,
                               int64_t samples, at::Generator* generator, double floor) {
  TORCH_CHECK(samples >= 1, "volume: at least one importance sample per ray");
  torch::NoGradGuard no_grad;
  const torch::Tensor edges = IntervalEdges(depths.detach(), segments);  // [R, S + 2]
  const int64_t rays = depths.size(0), s = depths.size(1) + 1;                // s intervals
  TORCH_CHECK(weights.size(1) == s, "volume: importance sampling needs one weight per interval");
  const auto opts = depths.options();
  const torch::Tensor mass = weights.detach().clamp_min(0) + floor;  // [R, s]
  const torch::Tensor cdf = torch::cat({torch::zeros({rays, 1}, opts), torch::cumsum(mass, 1)}, 1) /
                            mass.sum(1, true);  // [R, s + 1], 0 .. 1
  const torch::Tensor offsets = generator ? torch::rand({rays, samples}, *generator, opts.device(torch::kCPU)).to(opts)
                                          : torch::full({rays, samples}, 0.5, opts);
  const torch::Tensor u =
      ((torch::arange(samples, opts).view({1, samples}) + offsets) / double(samples)).clamp(0, 1).contiguous();
  const torch::Tensor above = torch::searchsorted(cdf.contiguous(), u, /*out_int32=*/false, /*right=*/true);
  const torch::Tensor index = (above - 1).clamp(0, s - 1);                    // the interval u falls in
  const torch::Tensor c0 = cdf.gather(1, index), c1 = cdf.gather(1, index + 1);
  const torch::Tensor e0 = edges.gather(1, index), e1 = edges.gather(1, index + 1);
  const torch::Tensor within = ((u - c0) / (c1 - c0).clamp_min(1e-12)).clamp(0, 1);
  return e0 + within * (e1 - e0);
}

Samples MergeSamples(const Samples& a, const Samples& b) {
  TORCH_CHECK(a.values.size() == b.values.size(), "volume: merging samples with different values");
  const torch::Tensor depths = torch::cat({a.depths, b.depths}, 1);
  const auto sorted = torch::sort(depths, /*stable=*/true, /*dim=*/1, /*descending=*/false);
  const torch::Tensor& order = std::get<1>(sorted);
  Samples merged{std::get<0>(sorted), {}};
  for (size_t i = 0; i < a.values.size(); ++i) {
    const torch::Tensor values = torch::cat({a.values[i], b.values[i]}, 1);
    std::vector<int64_t> shape(size_t(values.dim()), 1);
    shape[0] = order.size(0);
    shape[1] = order.size(1);
    torch::Tensor index = order.view(shape);
    index = index.expand(values.sizes());
    merged.values.push_back(values.gather(1, index));
  }
  return merged;
}

Composite CompositeSamples(const torch::Tensor& densities, const torch::Tensor& features, const torch::Tensor& depths,
                           const Segments& segments) {
  TORCH_CHECK(densities.dim() == 2 && depths.sizes() == densities.sizes(), "volume: densities and depths must be [R, S]");
  TORCH_CHECK(features.dim() == 3 && features.size(0) == densities.size(0) && features.size(1) == densities.size(1),
              "volume: features must be [R, S, C]");
  const torch::Tensor edges = IntervalEdges(depths, segments).to(densities.dtype());  // [R, S + 2]
  const int64_t rays = densities.size(0), s = densities.size(1) + 1;                // intervals
  const torch::Tensor lengths = (edges.narrow(1, 1, s) - edges.narrow(1, 0, s)).clamp_min(0);
  const torch::Tensor tau = IntervalValues(densities) * lengths;
  const torch::Tensor before =
      torch::cat({torch::zeros({rays, 1}, tau.options()), torch::cumsum(tau, 1).narrow(1, 0, s - 1)}, 1);
  const torch::Tensor weights = torch::exp(-before) * -torch::expm1(-tau);
  const torch::Tensor centres = (edges.narrow(1, 1, s) + edges.narrow(1, 0, s)) * 0.5;
  Composite out;
  out.weights = weights;
  out.features = (weights.unsqueeze(2) * IntervalValues(features)).sum(1);
  out.opacity = weights.sum(1);
  out.depth = (weights * centres).sum(1) + (1 - out.opacity) * segments.t_far.to(weights.dtype());
  return out;
}

}  // namespace headforge::volume
