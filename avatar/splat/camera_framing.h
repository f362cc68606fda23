// A camera's close-up of a box: zoomed in (never out), the principal point
// moved so that the box projects centred. Kept out of splat_camera.h, which
// the CUDA kernels include.
#pragma once

#include <algorithm>
#include <array>

#include "avatar/splat/splat_camera.h"

namespace headforge {

// `camera` zoomed so that the box [lo, hi] (world coordinates) projects
// centred and spans `fill` of the image on its longer side: a close-up of a
// head that fills little of a wide frame. Unchanged when the box already
// spans that much or a corner lies behind the camera.
inline SplatCamera FramedOn(const SplatCamera& camera, const std::array<double, 3>& lo,
                            const std::array<double, 3>& hi, double fill) {
  const auto& m = camera.cam_from_world;
  double u0 = 1e300, u1 = -1e300, v0 = 1e300, v1 = -1e300;
  for (int corner = 0; corner < 8; ++corner) {
    const double x = (corner & 1) ? hi[0] : lo[0], y = (corner & 2) ? hi[1] : lo[1], z = (corner & 4) ? hi[2] : lo[2];
    const double px = m[0] * x + m[1] * y + m[2] * z + m[3];
    const double py = m[4] * x + m[5] * y + m[6] * z + m[7];
    const double pz = m[8] * x + m[9] * y + m[10] * z + m[11];
    if (!(pz > 0)) return camera;
    const double u = camera.fx * px / pz + camera.cx, v = camera.fy * py / pz + camera.cy;
    u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
  }
  const double spans = std::max((u1 - u0) / camera.width, (v1 - v0) / camera.height);
  if (!(spans > 0) || spans >= fill) return camera;
  const double zoom = fill / spans;
  SplatCamera out = camera;
  out.fx = camera.fx * zoom;
  out.fy = camera.fy * zoom;
  // u' = zoom (u - cx) + cx' puts the box's centre at the image's centre.
  out.cx = 0.5 * (camera.width - 1) - zoom * (0.5 * (u0 + u1) - camera.cx);
  out.cy = 0.5 * (camera.height - 1) - zoom * (0.5 * (v0 + v1) - camera.cy);
  return out;
}

}  // namespace headforge
