#include "avatar/splat_fit_job.h"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

#include "avatar/train/splat_fit.h"

namespace headforge {
namespace {

// An 8-bit BGR image as a [3, H, W] RGB tensor in [0, 1].
torch::Tensor ToTensor(const cv::Mat& bgr) {
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  return torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kFloat32).permute({2, 0, 1}).clone();
}

cv::Mat ToImage(const torch::Tensor& rgb) {
  const torch::Tensor hwc =
      (rgb.clamp(0, 1) * 255.0).round().to(torch::kUInt8).permute({1, 2, 0}).contiguous();
  cv::Mat image(int(hwc.size(0)), int(hwc.size(1)), CV_8UC3, hwc.data_ptr());
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

// The rasterizer's camera for a pinhole camera (same conventions).
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

std::vector<PosedImage> ToPosed(const std::vector<SplatFitView>& views) {
  std::vector<PosedImage> out;
  for (const SplatFitView& v : views) out.push_back({ToSplatCamera(v.camera), ToTensor(v.image), v.name});
  return out;
}

std::vector<float> Flat(const torch::Tensor& t) {
  const torch::Tensor c = t.detach().to(torch::kFloat32).contiguous();
  return std::vector<float>(c.data_ptr<float>(), c.data_ptr<float>() + c.numel());
}

}  // namespace

Status CheckSplatFitDevice(const std::string& device) {
  torch::Device parsed = torch::kCPU;
  return ParseSplatFitDevice(device, &parsed);
}

Status RunSplatFit(const SplatFitOptions& options, const std::vector<SplatFitView>& train,
                   const std::vector<SplatFitView>& test, const SplatFitPoints& init, StatsLog* stats,
                   Progress* progress, SplatFitOutput* output) {
  const int64_t n = int64_t(init.sizes.size());
  if (init.positions.size() != size_t(3 * n) || init.colours.size() != size_t(3 * n)) {
    return Status::InvalidArgument("splat-fit: starting points, colours and sizes differ in count");
  }
  InitPoints points;
  points.positions = torch::from_blob(const_cast<float*>(init.positions.data()), {n, 3}, torch::kFloat32).clone();
  points.colours = torch::from_blob(const_cast<float*>(init.colours.data()), {n, 3}, torch::kFloat32).clone();
  points.sizes = torch::from_blob(const_cast<float*>(init.sizes.data()), {n}, torch::kFloat32).clone();
  SplatFitResult result;
  HF_RETURN_IF_ERROR(FitSplats(options, ToPosed(train), ToPosed(test), points, stats, progress, &result));
  torch::NoGradGuard no_grad;
  const GaussianParams& p = result.params;
  output->steps = result.steps;
  output->resumed_from = result.resumed_from;
  output->seconds = result.train_seconds;
  output->test_psnr = result.test_psnr;
  output->test_ssim = result.test_ssim;
  output->view_psnr = result.view_psnr;
  output->test_renders.clear();
  for (const torch::Tensor& r : result.test_renders) output->test_renders.push_back(ToImage(r));
  output->size = p.size();
  output->means = Flat(p.means);
  output->colours = Flat(torch::sigmoid(p.colour_logits));
  output->opacity_logits = Flat(p.opacity_logits);
  output->log_scales = Flat(p.log_scales);
  output->rotations = Flat(p.quats / p.quats.norm(2, 1, true));
  return Status::Ok();
}

}  // namespace headforge
