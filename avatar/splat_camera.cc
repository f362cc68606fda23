#include "avatar/splat_camera.h"

#include <cmath>

namespace headforge {

SplatCamera SplatCamera::FromPinhole(const PinholeCamera& camera) {
  SplatCamera out;
  const Eigen::Matrix3d r = camera.cam_from_world.linear();
  const Eigen::Vector3d t = camera.cam_from_world.translation();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out.cam_from_world[4 * i + j] = r(i, j);
    out.cam_from_world[4 * i + 3] = t[i];
  }
  out.fx = camera.fx;
  out.fy = camera.fy;
  out.cx = camera.cx;
  out.cy = camera.cy;
  out.width = camera.width;
  out.height = camera.height;
  return out;
}

SplatCamera SplatCamera::Downscaled(double factor) const {
  SplatCamera out = *this;
  out.width = static_cast<int>(std::lround(width / factor));
  out.height = static_cast<int>(std::lround(height / factor));
  // Pixel centres at integers: x' = (x + 0.5) / factor - 0.5.
  out.fx = fx / factor;
  out.fy = fy / factor;
  out.cx = (cx + 0.5) / factor - 0.5;
  out.cy = (cy + 0.5) / factor - 0.5;
  return out;
}

bool SplatOptions::Check(std::string* why) const {
  if (!(near_plane > 0)) {
    *why = "near_plane must be positive";
    return false;
  }
  if (!(far_plane > near_plane)) {
    *why = "far_plane must be beyond near_plane";
    return false;
  }
  if (!(eps2d >= 0)) {
    *why = "eps2d must be zero or positive";
    return false;
  }
  if (!(clip_margin >= 0)) {
    *why = "clip_margin must be zero or positive";
    return false;
  }
  return true;
}

}  // namespace headforge
