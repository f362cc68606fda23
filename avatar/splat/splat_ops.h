// Differentiable Gaussian splatting, as named stages:
//   ProjectGaussians -> IntersectTiles -> RasterizeGaussians,
// composed by RenderGaussians. Each differentiable stage is a LibTorch
// autograd Function with an analytic backward; every stage has one signature
// on every device and picks its kernels from the tensors' device.
//
// Shapes: N Gaussians, C feature channels (any C >= 1), H x W pixels,
// M Gaussian-tile intersections. float32 or float64 throughout.
#pragma once

#include <torch/types.h>

#include "avatar/splat/splat_camera.h"

namespace headforge {

struct ProjectResult {
  torch::Tensor means2d;  // [N, 2] pixel position of each centre
  torch::Tensor conics;   // [N, 3] (a, b, c): inverse 2D covariance [[a, b], [b, c]]
  torch::Tensor depths;   // [N] camera-frame z, metres
  torch::Tensor radii;    // [N] int32, screen radius in pixels; 0 = culled
};

// Projects 3D Gaussians into `camera` with the EWA approximation (local affine
// projection) and the eps2d low-pass filter. Culls Gaussians behind the near
// plane, beyond the far plane, with a degenerate 2D covariance, or entirely
// off screen; culled ones get radius 0, zero outputs and zero gradients.
// Differentiable with respect to means, quats and log_scales.
ProjectResult ProjectGaussians(const torch::Tensor& means,       // [N, 3] world
                               const torch::Tensor& quats,       // [N, 4] (w, x, y, z), any norm > 0
                               const torch::Tensor& log_scales,  // [N, 3] log of the axis scales
                               const SplatCamera& camera, const SplatOptions& options = {});

struct TileIntersections {
  int tiles_x = 0, tiles_y = 0;
  torch::Tensor tile_offsets;  // [tiles_y * tiles_x + 1] int32: tile t's list is [offsets[t], offsets[t+1])
  torch::Tensor gaussian_ids;  // [M] int32, near to far within each tile
};

// Lists, for every kSplatTileSize^2 screen tile, the Gaussians whose 3-sigma
// square overlaps it, sorted by depth (ties by index). Not differentiable.
TileIntersections IntersectTiles(const torch::Tensor& means2d,  // [N, 2]
                                 const torch::Tensor& radii,    // [N] int32
                                 const torch::Tensor& depths,   // [N]
                                 int width, int height);

struct RasterizeResult {
  torch::Tensor image;  // [C, H, W] sum of w_i f_i + T_final * background
  torch::Tensor alpha;  // [H, W] 1 - T_final
};

// Front-to-back alpha compositing per pixel: alpha_i = min(0.999, o_i *
// exp(-q_i / 2)) with q_i the conic's quadratic form at the pixel centre;
// Gaussians with alpha_i < 1/255 are skipped, and a pixel stops before the
// Gaussian that would take its transmittance below 1e-4. Differentiable with
// respect to means2d, conics, features, opacities and background.
RasterizeResult RasterizeGaussians(const torch::Tensor& means2d,    // [N, 2]
                                   const torch::Tensor& conics,     // [N, 3]
                                   const torch::Tensor& features,   // [N, C]
                                   const torch::Tensor& opacities,  // [N] in [0, 1]
                                   const torch::Tensor& background, // [C], or undefined for zeros
                                   const TileIntersections& tiles, int width, int height);

struct SplatRenderOptions {
  SplatOptions splat;
  // Also render the expected depth (sum w_i z_i / alpha), metres.
  bool depth = false;
};

struct SplatRenderResult {
  torch::Tensor image;    // [C, H, W]
  torch::Tensor alpha;    // [H, W]
  torch::Tensor depth;    // [H, W] expected depth where alpha > 0, else 0 (if requested)
  torch::Tensor means2d;  // [N, 2] projected centres (call retain_grad() for screen-space gradients)
  torch::Tensor radii;    // [N] int32
};

// The three stages in one call.
SplatRenderResult RenderGaussians(const torch::Tensor& means,       // [N, 3]
                             const torch::Tensor& quats,       // [N, 4]
                             const torch::Tensor& log_scales,  // [N, 3]
                             const torch::Tensor& opacities,   // [N] in [0, 1]
                             const torch::Tensor& features,    // [N, C]
                             const torch::Tensor& background,  // [C] or undefined
                             const SplatCamera& camera, const SplatRenderOptions& options = {});

}  // namespace headforge
