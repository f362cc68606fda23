// A plain-tensor reference of the splatting stages: dense over every
// (pixel, Gaussian) pair, differentiated by LibTorch's autograd. It follows
// the kernels' rules exactly (EWA projection, culling, 3-sigma tiles,
// alpha threshold and clamp, early stop) and is meant for tests at small
// sizes only.
#pragma once

#include <torch/types.h>

#include "avatar/splat/splat_ops.h"

namespace headforge::splat_reference {

ProjectResult Project(const torch::Tensor& means, const torch::Tensor& quats,
                      const torch::Tensor& log_scales, const SplatCamera& camera,
                      const SplatOptions& options = {});

// Gaussians are composited in order of `depths` (ties by index) and only on
// the tiles their radius covers, as IntersectTiles does.
RasterizeResult Rasterize(const torch::Tensor& means2d, const torch::Tensor& conics,
                          const torch::Tensor& features, const torch::Tensor& opacities,
                          const torch::Tensor& background, const torch::Tensor& radii,
                          const torch::Tensor& depths, int width, int height);

}  // namespace headforge::splat_reference
