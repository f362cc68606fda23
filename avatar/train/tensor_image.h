// Between OpenCV's 8-bit BGR images and [3, H, W] float RGB tensors in [0, 1],
// and the project's pinhole camera to the rasterizer's and back (whose pose
// as an isometry is in view_camera.h).
#pragma once

#include <opencv2/core.hpp>
#include <torch/types.h>

#include "avatar/splat/splat_camera.h"
#include "avatar/train/view_camera.h"
#include "core/mesh_renderer.h"

namespace headforge {

torch::Tensor ImageToTensor(const cv::Mat& bgr);       // CV_8UC3 -> [3, H, W]
torch::Tensor MaskToTensor(const cv::Mat& mask);       // CV_8U (0 / 255) -> [1, H, W] in {0, 1}
cv::Mat TensorToImage(const torch::Tensor& rgb);       // [3, H, W] (clamped to [0, 1]) -> CV_8UC3
SplatCamera ToSplatCamera(const PinholeCamera& camera);
PinholeCamera ToPinholeCamera(const SplatCamera& camera);

}  // namespace headforge
