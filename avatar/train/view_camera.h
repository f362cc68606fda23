// The rasterizer camera's pose as an isometry, both ways, and its image on a
// square canvas (kept apart from the image conversions so that a
// LibTorch-only build has them).
#pragma once

#include <Eigen/Geometry>

#include "avatar/splat/splat_camera.h"

namespace headforge {

Eigen::Isometry3d CameraPose(const SplatCamera& camera);  // its cam_from_world
void SetCameraPose(const Eigen::Isometry3d& cam_from_world, SplatCamera* camera);

// A camera's image drawn on a square canvas of `side` px: the same view
// scaled so its longer side is `side`, centred; [x0, x0 + width) x [y0, y0 +
// height) is the image on the canvas.
struct SquareCanvas {
  SplatCamera camera;
  int x0 = 0, y0 = 0, width = 0, height = 0;
};
SquareCanvas MakeSquareCanvas(const SplatCamera& camera, int side);

}  // namespace headforge
