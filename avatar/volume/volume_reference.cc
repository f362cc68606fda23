#include "avatar/volume/volume_reference.h"

#include <cmath>

namespace headforge::volume_reference {
namespace {

bool Inside(const Vec3& p, const volume::Box& box) {
  for (int a = 0; a < 3; ++a)
    if (p[a] < box.min[a] || p[a] > box.max[a]) return false;
  return true;
}

Vec3 At(const Vec3& origin, const Vec3& direction, double t) {
  return {origin[0] + t * direction[0], origin[1] + t * direction[1], origin[2] + t * direction[2]};
}

}  // namespace

bool MarchSegment(const Vec3& origin, const Vec3& direction, const volume::Box& box, double step, double max_depth,
                  double* t_near, double* t_far) {
  bool found = false;
  for (double t = 0; t <= max_depth; t += step) {
    if (!Inside(At(origin, direction, t), box)) continue;
    if (!found) *t_near = t;
    *t_far = t;
    found = true;
  }
  return found;
}

Composited Composite(const std::vector<double>& densities, const std::vector<std::vector<double>>& features,
                     const std::vector<double>& depths, double t_near, double t_far) {
  const size_t s = depths.size();
  const size_t c = features.empty() ? 0 : features[0].size();
  Composited out;
  out.features.assign(c, 0.0);
  out.weights.assign(s + 1, 0.0);
  double transmittance = 1;
  for (size_t k = 0; k <= s; ++k) {
    // Interval k runs from the sample before it (or t_near) to the one after
    // it (or t_far), with the mean of the two samples' values.
    const size_t a = k == 0 ? 0 : k - 1, b = k == s ? s - 1 : k;
    const double start = k == 0 ? t_near : depths[k - 1];
    const double end = k == s ? t_far : depths[k];
    const double sigma = 0.5 * (densities[a] + densities[b]);
    const double alpha = 1 - std::exp(-sigma * std::max(end - start, 0.0));
    const double weight = transmittance * alpha;
    out.weights[k] = weight;
    for (size_t i = 0; i < c; ++i) out.features[i] += weight * 0.5 * (features[a][i] + features[b][i]);
    out.opacity += weight;
    out.depth += weight * 0.5 * (start + end);
    transmittance *= 1 - alpha;
  }
  out.depth += (1 - out.opacity) * t_far;
  return out;
}

std::array<double, 4> RenderDense(const Vec3& origin, const Vec3& direction, const volume::Box& box,
                                  const std::function<double(const Vec3&)>& density,
                                  const std::function<Vec3(const Vec3&)>& colour, double max_depth, int steps) {
  const double dt = max_depth / steps;
  double optical_depth = 0;
  std::array<double, 4> out = {0, 0, 0, 0};
  for (int i = 0; i < steps; ++i) {
    const Vec3 p = At(origin, direction, (i + 0.5) * dt);
    if (!Inside(p, box)) continue;
    const double sigma = density(p);
    // The step's own absorption exactly (constant field over the step).
    const double weight = std::exp(-optical_depth) * (1 - std::exp(-sigma * dt));
    const Vec3 c = colour(p);
    for (int k = 0; k < 3; ++k) out[k] += weight * c[k];
    optical_depth += sigma * dt;
  }
  out[3] = 1 - std::exp(-optical_depth);
  return out;
}

}  // namespace headforge::volume_reference
