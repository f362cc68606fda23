#include "avatar/train/tensor_image.h"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

namespace headforge {

torch::Tensor ImageToTensor(const cv::Mat& bgr) {
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  return torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kFloat32).permute({2, 0, 1}).clone();
}

torch::Tensor MaskToTensor(const cv::Mat& mask) {
  cv::Mat f;
  mask.convertTo(f, CV_32F, 1.0 / 255.0);
  return (torch::from_blob(f.data, {1, f.rows, f.cols}, torch::kFloat32) > 0.5).to(torch::kFloat32);
}

cv::Mat TensorToImage(const torch::Tensor& rgb) {
  const torch::Tensor hwc =
      (rgb.detach().cpu().to(torch::kFloat32).clamp(0, 1) * 255.0).round().to(torch::kUInt8).permute({1, 2, 0}).contiguous();
  cv::Mat image(int(hwc.size(0)), int(hwc.size(1)), CV_8UC3, hwc.data_ptr());
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

SplatCamera ToSplatCamera(const PinholeCamera& camera) {
  SplatCamera out;
  const Eigen::Matrix3d r = camera.cam_from_world.linear();
  const Eigen::Vector3d t = camera.cam_from_world.translation();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out.cam_from_world[4 * i + j] = r(i, j);
    out.cam_from_world[4 * i + 3] = t[i];
  }
  out.fx = camera.fx;
  out.fy = camera.fy;
  out.cx = camera.cx;
  out.cy = camera.cy;
  out.width = camera.width;
  out.height = camera.height;
  return out;
}

}  // namespace headforge
