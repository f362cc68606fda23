// Backend kernels behind splat_ops.h; one set per device, same arguments.
// Inputs are validated and made contiguous by splat_ops.cc, outputs are
// allocated there. Internal to avatar/.
#pragma once

#include <torch/types.h>

#include "avatar/splat_camera.h"

namespace headforge::splat {

// The camera and options as the projection kernels use them.
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

namespace cpu {

void ProjectForward(const torch::Tensor& means, const torch::Tensor& quats,
                    const torch::Tensor& log_scales, const ProjectParams& params,
                    torch::Tensor& means2d, torch::Tensor& conics, torch::Tensor& depths,
                    torch::Tensor& radii);

void ProjectBackward(const torch::Tensor& means, const torch::Tensor& quats,
                     const torch::Tensor& log_scales, const torch::Tensor& radii,
                     const ProjectParams& params, const torch::Tensor& v_means2d,
                     const torch::Tensor& v_conics, const torch::Tensor& v_depths,
                     torch::Tensor& v_means, torch::Tensor& v_quats, torch::Tensor& v_log_scales);

// Returns (tile_offsets, gaussian_ids).
std::pair<torch::Tensor, torch::Tensor> IntersectTiles(const torch::Tensor& means2d,
                                                       const torch::Tensor& radii,
                                                       const torch::Tensor& depths, int tiles_x,
                                                       int tiles_y);

// Fills image [C, H, W], transmittance [H, W] (T_final) and last [H, W]
// (int32: how many entries of its tile's list a pixel went through).
void RasterizeForward(const torch::Tensor& means2d, const torch::Tensor& conics,
                      const torch::Tensor& features, const torch::Tensor& opacities,
                      const torch::Tensor& background, const torch::Tensor& tile_offsets,
                      const torch::Tensor& gaussian_ids, int width, int height,
                      torch::Tensor& image, torch::Tensor& transmittance, torch::Tensor& last);

// Gradients for means2d, conics, features and opacities (background's is a
// plain reduction done by the caller).
void RasterizeBackward(const torch::Tensor& means2d, const torch::Tensor& conics,
                       const torch::Tensor& features, const torch::Tensor& opacities,
                       const torch::Tensor& background, const torch::Tensor& tile_offsets,
                       const torch::Tensor& gaussian_ids, int width, int height,
                       const torch::Tensor& transmittance, const torch::Tensor& last,
                       const torch::Tensor& v_image, const torch::Tensor& v_alpha,
                       torch::Tensor& v_means2d, torch::Tensor& v_conics,
                       torch::Tensor& v_features, torch::Tensor& v_opacities);

}  // namespace cpu
}  // namespace headforge::splat
