// Volume rendering of a field bounded by an axis-aligned box, in four named
// stages, each a function of plain tensors: ray generation (a pinhole
// camera's pixel rays), ray/box intersection (the slab test), sampling
// (stratified depths in the box, then importance depths drawn from the
// coarse pass's weights) and compositing (the emission-absorption quadrature).
// Made of LibTorch operations, so autograd differentiates them and they run
// on whichever device their tensors are on. volume_reference.h holds a plain
// double-precision version of each for the tests.
//
// Quadrature: the samples' depths d_0 <= ... <= d_{S-1} and the ray's
// segment [t_near, t_far] make S + 1 intervals with edges t_near, d_0, ...,
// d_{S-1}, t_far. Between two samples the field is the mean of its values at
// them (the trapezoid rule, which stays second order when importance
// sampling packs the samples unevenly); on the two end pieces it is the
// nearest sample's. So the intervals cover the whole segment whatever the
// depths, and a uniform box is integrated exactly. With delta_k the lengths,
// tau_k = sigma_k delta_k, T_k = exp(-sum_{j<k} tau_j), alpha_k =
// 1 - exp(-tau_k), weight_k = T_k alpha_k. Transmittance is summed in the
// exponent, never multiplied out, so hundreds of dense samples underflow to
// exact zeros, not to NaN.
#pragma once

#include <torch/types.h>

#include <array>
#include <vector>

#include "avatar/splat/splat_camera.h"

namespace headforge::volume {

struct Rays {
  torch::Tensor origins;     // [R, 3], the camera centre in the world
  torch::Tensor directions;  // [R, 3], unit length
};

// The rays through the centres of `camera`'s pixels, row by row (ray
// y * width + x goes through pixel (x, y)), in the world cam_from_world maps
// from, as float32 on `device`.
Rays GenerateRays(const SplatCamera& camera, torch::Device device = torch::kCPU);

struct Box {
  std::array<double, 3> min = {-1, -1, -1}, max = {1, 1, 1};
  // `point` [..., 3] mapped to [-1, 1]^3 over the box.
  torch::Tensor Normalise(const torch::Tensor& point) const;
};

struct Segments {
  torch::Tensor t_near, t_far;  // [R]; both 0 where the ray misses
  torch::Tensor hit;            // [R] bool: t_far > t_near
};

// The slab test. A ray that starts inside the box starts its segment at 0;
// one parallel to a pair of faces hits only if its origin lies between them
// (inclusive); one that only grazes an edge or a corner (a segment of zero
// length) misses.
Segments IntersectBox(const Rays& rays, const Box& box);

// `samples` depths per ray, one in each of `samples` equal bins of its
// segment: at the bins' centres without `generator`, uniformly within them
// with it. [R, S], increasing along each ray.
torch::Tensor StratifiedDepths(const Segments& segments, int64_t samples, at::Generator* generator = nullptr);

// `samples` depths per ray drawn from the piecewise-constant density whose
// mass on interval k of `depths` (the quadrature's S + 1 intervals, above)
// is weights_k + `floor` (the floor keeps rays with no weight sampling their
// whole segment): by the inverse CDF at (j + 0.5) / samples without
// `generator`, at (j + u_j) / samples with it. [R, samples], increasing, no
// gradient.
torch::Tensor ImportanceDepths(const Segments& segments, const torch::Tensor& depths, const torch::Tensor& weights,
                               int64_t samples, at::Generator* generator = nullptr, double floor = 1e-3);

// Two sets of samples along the same rays, one sorted set: depths [R, S1] and
// [R, S2] and the values at them ([R, S1, ...] and [R, S2, ...], any number
// of trailing dimensions, each list in the depths' order) merged in depth
// order. Gradients flow to both sets' values.
struct Samples {
  torch::Tensor depths;                // [R, S]
  std::vector<torch::Tensor> values;   // each [R, S, ...]
};
Samples MergeSamples(const Samples& a, const Samples& b);

struct Composite {
  torch::Tensor features;  // [R, C]: sum_k weight_k f_k (no background)
  torch::Tensor opacity;   // [R]: sum_k weight_k = 1 - T_{S+1}
  torch::Tensor depth;     // [R]: sum_k weight_k (interval k's centre) + (1 - opacity) t_far
  torch::Tensor weights;   // [R, S + 1], one per interval
};

// densities [R, S] (>= 0), features [R, S, C] at depths [R, S] (increasing
// along each ray, within its segment).
Composite CompositeSamples(const torch::Tensor& densities, const torch::Tensor& features,
                           const torch::Tensor& depths, const Segments& segments);

// The quadrature's interval edges [R, S + 2] (above).
torch::Tensor IntervalEdges(const torch::Tensor& depths, const Segments& segments);
// values [R, S, ...] at the samples -> [R, S + 1, ...] on the intervals.
torch::Tensor IntervalValues(const torch::Tensor& values);

}  // namespace headforge::volume
