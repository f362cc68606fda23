#include "avatar/train/view_camera.h"

#include <algorithm>
#include <cmath>

namespace headforge {

Eigen::Isometry3d CameraPose(const SplatCamera& camera) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) pose.matrix()(i, j) = camera.cam_from_world[size_t(4 * i + j)];
  return pose;
}

void SetCameraPose(const Eigen::Isometry3d& cam_from_world, SplatCamera* camera) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) camera->cam_from_world[size_t(4 * i + j)] = cam_from_world.matrix()(i, j);
}

SquareCanvas MakeSquareCanvas(const SplatCamera& camera, int side) {
  const double scale = double(side) / std::max(camera.width, camera.height);
  SquareCanvas canvas;
  canvas.width = std::clamp(int(std::lround(camera.width * scale)), 1, side);
  canvas.height = std::clamp(int(std::lround(camera.height * scale)), 1, side);
  canvas.x0 = (side - canvas.width) / 2;
  canvas.y0 = (side - canvas.height) / 2;
  canvas.camera = camera;
  canvas.camera.width = canvas.camera.height = side;
  canvas.camera.fx = camera.fx * scale;
  canvas.camera.fy = camera.fy * scale;
  canvas.camera.cx = (camera.cx + 0.5) * scale - 0.5 + canvas.x0;
  canvas.camera.cy = (camera.cy + 0.5) * scale - 0.5 + canvas.y0;
  return canvas;
}

}  // namespace headforge
