#include "avatar/train/view_scores.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "avatar/metrics/image_metrics.h"

namespace headforge {

ViewScores ScoreRender(const torch::Tensor& render, const torch::Tensor& image, const torch::Tensor& mask,
                       const torch::Tensor& background) {
  torch::NoGradGuard no_grad;
  const torch::Tensor r = render.detach().to(torch::kFloat64).cpu().clamp(0, 1);
  const torch::Tensor m = mask.to(torch::kFloat64).cpu();
  const torch::Tensor target = image.to(torch::kFloat64).cpu() * m + background.to(torch::kFloat64).cpu().view({3, 1, 1}) * (1 - m);
  const torch::Tensor squared = (r - target).pow(2);
  const double inside = std::max(m.sum().item<double>(), 1.0);
  ViewScores s;
  s.has_head = m.sum().item<double>() >= 1;
  const double mse_masked = (squared * m).sum().item<double>() / (3 * inside);
  const double mse_full = squared.mean().item<double>();
  s.psnr_masked = 10 * std::log10(1 / std::max(mse_masked, 1e-12));
  s.psnr_full = 10 * std::log10(1 / std::max(mse_full, 1e-12));
  s.l1_masked = ((r - target).abs() * m).sum().item<double>() / (3 * inside);
  const torch::Tensor map = SsimMap(r.unsqueeze(0), target.unsqueeze(0))[0].mean(0, true);  // [1, H, W]
  s.ssim_masked = (map * m).sum().item<double>() / inside;
  s.ssim_full = map.mean().item<double>();
  s.sharpness = 255 * Sharpness(r, m);
  s.sharpness_truth = 255 * Sharpness(target, m);
  s.sd = s.sharpness - s.sharpness_truth;
  return s;
}

torch::Tensor ComparisonStrip(const torch::Tensor& render, const torch::Tensor& image, const torch::Tensor& mask,
                              double background) {
  const torch::Tensor shown = image * mask + background * (1 - mask);
  const torch::Tensor error = ((render - shown).abs() * 4).clamp(0, 1);
  return torch::cat({render, shown, error}, 2);
}

void SetSummaryScores(const ViewScores& held_out, int views, const ViewScores& training_views, TrainSummary* summary) {
  summary->test_views = views;
  summary->psnr_masked = held_out.psnr_masked;
  summary->ssim_masked = held_out.ssim_masked;
  summary->psnr_full = held_out.psnr_full;
  summary->ssim_full = held_out.ssim_full;
  summary->l1_masked = held_out.l1_masked;
  summary->train_psnr_masked = training_views.psnr_masked;
}

ViewScores MeanScores(const std::vector<ViewScores>& scores) {
  ViewScores mean;
  const double heads = double(std::count_if(scores.begin(), scores.end(), [](const ViewScores& s) { return s.has_head; }));
  mean.has_head = heads > 0;
  for (const ViewScores& s : scores) {
    if (s.has_head) {
      mean.psnr_masked += s.psnr_masked / heads;
      mean.ssim_masked += s.ssim_masked / heads;
      mean.l1_masked += s.l1_masked / heads;
      mean.sharpness += s.sharpness / heads;
      mean.sharpness_truth += s.sharpness_truth / heads;
      mean.sd += s.sd / heads;
    }
    mean.psnr_full += s.psnr_full / double(scores.size());
    mean.ssim_full += s.ssim_full / double(scores.size());
  }
  return mean;
}

nlohmann::json ScoresJson(const ViewScores& s, bool with_view) {
  nlohmann::json j = {{"psnr_masked", s.psnr_masked}, {"ssim_masked", s.ssim_masked}, {"psnr", s.psnr_full},
                      {"ssim", s.ssim_full},          {"l1_masked", s.l1_masked},     {"sharpness", s.sharpness},
                      {"sharpness_truth", s.sharpness_truth}, {"sd", s.sd}};
  if (with_view) {
    j["frame"] = s.frame;
    j["camera"] = s.camera;
  }
  return j;
}

double MeanRenderMs(const std::vector<ViewScores>& scores) {
  double ms = 0;
  for (size_t i = 1; i < scores.size(); ++i) ms += scores[i].render_ms / double(scores.size() - 1);
  return ms;
}

}  // namespace headforge
