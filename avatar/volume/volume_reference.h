// A plain double-precision reference of the volume renderer's stages, one ray
// at a time, for tests: the segment found by marching (no slab test), the
// textbook compositing loop (transmittance multiplied out), and the rendering
// integral by a dense Riemann sum of a field given as functions.
#pragma once

#include <array>
#include <functional>
#include <vector>

#include "avatar/volume/volume_render.h"

namespace headforge::volume_reference {

using Vec3 = std::array<double, 3>;

// The first and last depths >= 0 at which the ray is inside `box`, marching
// in steps of `step` up to `max_depth`; false when no step lands inside.
bool MarchSegment(const Vec3& origin, const Vec3& direction, const volume::Box& box, double step, double max_depth,
                  double* t_near, double* t_far);

struct Composited {
  std::vector<double> features;  // C
  double opacity = 0, depth = 0;
  std::vector<double> weights;   // S + 1, one per interval
};

// The quadrature of volume_render.h for one ray, in loops: densities [S],
// features [S][C], depths [S] within [t_near, t_far].
Composited Composite(const std::vector<double>& densities, const std::vector<std::vector<double>>& features,
                     const std::vector<double>& depths, double t_near, double t_far);

// int_0^inf T(t) sigma(x(t)) c(x(t)) dt over the part of the ray in `box`
// (found by testing each step), by the midpoint rule with `steps` steps over
// [0, max_depth]; returns the colour (3) and the opacity 1 - T.
std::array<double, 4> RenderDense(const Vec3& origin, const Vec3& direction, const volume::Box& box,
                                  const std::function<double(const Vec3&)>& density,
                                  const std::function<Vec3(const Vec3&)>& colour, double max_depth, int steps);

}  // namespace headforge::volume_reference
