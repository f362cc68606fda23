// Gaussians as glTF 2.0 binary with the KHR_gaussian_splatting extension:
// a POINTS primitive with POSITION, KHR_gaussian_splatting:ROTATION (unit
// quaternion x, y, z, w), :SCALE (linear standard deviations), :OPACITY
// (after the sigmoid, in [0, 1]), :SH_DEGREE_0_COEF_0 (so that colour =
// 0.5 + 0.2820948 * coefficient), and COLOR_0 (RGB and opacity) for viewers
// without the extension, which then draw a point cloud.
#pragma once

#include "avatar/avatar_export.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

Status WriteGaussianGlb(const fs::path& path, const AvatarSplats& splats);

// The Gaussian blendshapes as one GLB: the neutral Gaussians as
// WriteGaussianGlb writes them, and a morph target per expression, named in
// the mesh's extras.targetNames (ARKit's names): POSITION (sparse),
// KHR_gaussian_splatting:ROTATION (x, y, z, w over the neutral quaternion's
// length: normalise after the weighted sum), :SCALE (linearised at the
// neutral scale, exp(log-scale) times the log-scale's offset) and
// :SH_DEGREE_0_COEF_0 (the colour's offset / 0.2820948).
Status WriteGaussianBlendshapeGlb(const fs::path& path, const AvatarBlendshapes& shapes);

}  // namespace headforge
