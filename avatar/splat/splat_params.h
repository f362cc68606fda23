// The camera and options as the projection kernels use them, free of LibTorch
// so that the CUDA kernels (splat_cuda.cu) share it with the CPU ones.
// Internal to avatar/.
#pragma once

#include "avatar/splat/splat_camera.h"

namespace headforge::splat {

struct ProjectParams {
  double rotation[9];     // cam_from_world, row-major
  double translation[3];
  double fx, fy, cx, cy;
  int width, height;
  double near_plane, far_plane, eps2d;
  // Limits of x/z and y/z where the projection's Jacobian is evaluated.
  double lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos;

  static ProjectParams From(const SplatCamera& camera, const SplatOptions& options);
};

// Constants shared by every backend's rasterize kernels.
constexpr double kMinAlpha = 1.0 / 255.0;
constexpr double kMaxAlpha = 0.999;
constexpr double kMinTransmittance = 1e-4;

// Columns of the rasterize backward's per-Gaussian gradient rows (every
// backend's, and of the CUDA kernels' per-entry rows): mean x, y; conic a, b,
// c; opacity; then the C features from kGradFeatures on.
enum GradientColumn : int { kGradMx, kGradMy, kGradA, kGradB, kGradC, kGradO, kGradFeatures };

}  // namespace headforge::splat
