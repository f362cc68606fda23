#include "avatar/splat/splat_camera.h"

#include <cmath>

namespace headforge {

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
