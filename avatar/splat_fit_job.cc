#include "avatar/splat_fit_job.h"

#include <torch/torch.h>

#include "avatar/torch_runtime.h"
#include "avatar/train/splat_fit.h"
#include "avatar/train/tensor_image.h"

namespace headforge {
namespace {

std::vector<PosedImage> ToPosed(const std::vector<SplatFitView>& views) {
  std::vector<PosedImage> out;
  for (const SplatFitView& v : views) out.push_back({ToSplatCamera(v.camera), ImageToTensor(v.image), v.name});
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
  UseTensorThreads();
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
  for (const torch::Tensor& r : result.test_renders) output->test_renders.push_back(TensorToImage(r));
  output->size = p.size();
  output->means = Flat(p.means);
  output->colours = Flat(torch::sigmoid(p.colour_logits));
  output->opacity_logits = Flat(p.opacity_logits);
  output->log_scales = Flat(p.log_scales);
  output->rotations = Flat(p.quats / p.quats.norm(2, 1, true));
  return Status::Ok();
}

}  // namespace headforge
