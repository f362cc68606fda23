// Gaussian splat clouds in the PLY layout of the original 3D Gaussian
// Splatting code, which web and game-engine viewers read:
//   x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity scale_0..2 rot_0..3
// as binary little-endian floats, with opacity as a logit, log scales, the
// rotation quaternion (w, x, y, z) unnormalised, and spherical-harmonic
// coefficients zero-padded to degree 3 (f_rest channel-major: 15 per channel),
// because some viewers accept nothing else.
#pragma once

#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct GaussianCloud {
  int sh_degree = 0;               // 0..3: coefficients per channel (deg + 1)^2
  std::vector<float> means;        // [N, 3] metres
  std::vector<float> sh_dc;        // [N, 3] degree-0 coefficient per channel (RGB)
  std::vector<float> sh_rest;      // [N, 3, K] channel-major, K = (deg + 1)^2 - 1
  std::vector<float> opacities;    // [N] logit
  std::vector<float> log_scales;   // [N, 3]
  std::vector<float> rotations;    // [N, 4] w, x, y, z

  size_t size() const { return opacities.size(); }
  int RestPerChannel() const { return (sh_degree + 1) * (sh_degree + 1) - 1; }
  // Checks that every array has the size N implies.
  Status Check() const;
};

Status WriteGaussianPly(const fs::path& path, const GaussianCloud& cloud);
// Reads a binary little-endian PLY with at least x y z, f_dc_*, opacity,
// scale_*, rot_*; f_rest_* (if any) sets the degree. Float or double properties.
Status ReadGaussianPly(const fs::path& path, GaussianCloud* cloud);

}  // namespace headforge
