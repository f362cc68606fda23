// The camera and settings of the Gaussian rasterizer, kept free of LibTorch
// and of the rest of the project (the CUDA kernels include it too).
#pragma once

#include <array>
#include <string>

namespace headforge {

// A pinhole camera in the project's conventions: OpenCV axes, pixel centres
// at integer coordinates (the top-left pixel's centre is (0, 0)).
struct SplatCamera {
  // cam_from_world as a row-major 3x4 matrix [R | t].
  std::array<double, 12> cam_from_world = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  double fx = 500, fy = 500, cx = 255.5, cy = 255.5;  // pixels
  int width = 512, height = 512;

  // The same camera rendering `factor` times fewer pixels per side.
  SplatCamera Downscaled(double factor) const;
};

struct SplatOptions {
  // Gaussians whose centre is nearer than this (camera z, metres) are culled.
  double near_plane = 0.01;
  // ... or farther than this.
  double far_plane = 1e4;
  // Added to both diagonal entries of every 2D covariance (pixels squared): a
  // low-pass filter that keeps sub-pixel Gaussians at least a pixel wide.
  double eps2d = 0.3;
  // The Jacobian of the projection is evaluated at the view direction clamped
  // to the field of view widened by this fraction of the image on each side,
  // which keeps Gaussians far outside the image from exploding.
  double clip_margin = 0.3;

  bool Check(std::string* why) const;
};

// Side of the square screen tiles the rasterizer works in, pixels.
inline constexpr int kSplatTileSize = 16;

}  // namespace headforge
