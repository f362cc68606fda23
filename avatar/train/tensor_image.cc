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
  SetCameraPose(camera.cam_from_world, &out);
  out.fx = camera.fx;
  out.fy = camera.fy;
  out.cx = camera.cx;
  out.cy = camera.cy;
  out.width = camera.width;
  out.height = camera.height;
  return out;
}

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

}  // namespace headforge
