#include "avatar/train/tensor_image.h"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

#include "avatar/train/dataset.h"
#include "avatar/train/image_file.h"
#include "core/image_io.h"

namespace headforge {

torch::Tensor ImageToTensor(const cv::Mat& bgr) {
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return ImageFromBytes(torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kUInt8).permute({2, 0, 1}));
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

Status WriteTensorImage(const fs::path& path, const torch::Tensor& rgb) {
  return WriteImageAtomic(path, TensorToImage(rgb));
}

bool ImageFilesWritten() { return true; }

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

PinholeCamera ToPinholeCamera(const SplatCamera& camera) {
  PinholeCamera out;
  out.cam_from_world = CameraPose(camera);
  out.fx = camera.fx;
  out.fy = camera.fy;
  out.cx = camera.cx;
  out.cy = camera.cy;
  out.width = camera.width;
  out.height = camera.height;
  return out;
}

}  // namespace headforge
