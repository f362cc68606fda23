// Scoring a model's renders against the frames over the person's mask: what
// every model's evaluation (eval.json, the held-out lines of stats.jsonl, the
// summary train prints) is made of.
#pragma once

#include <torch/types.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "avatar/avatar_train.h"

namespace headforge {

struct ViewScores {
  int frame = 0;
  std::string camera;
  double psnr_masked = 0, ssim_masked = 0, psnr_full = 0, ssim_full = 0, l1_masked = 0;
  // Mean gradient magnitude over the head (grey levels per pixel, x 255) of
  // the render and of the frame; SD = render's - frame's (negative: blurrier).
  double sharpness = 0, sharpness_truth = 0, sd = 0;
  bool has_head = true;  // false: the mask is empty and the masked figures mean nothing
  // Posing and drawing the view, its image back on the CPU (where measured).
  double render_ms = 0;
};

// `render` [3, H, W] against `image` [3, H, W] on `mask` [1, H, W], the
// image's background set to `background` [3] (the render's own).
ViewScores ScoreRender(const torch::Tensor& render, const torch::Tensor& image, const torch::Tensor& mask,
                       const torch::Tensor& background);
// render | image (grey `background` outside `mask`) | error x 4, side by
// side: [3, H, 3W], for the images a person checks.
torch::Tensor ComparisonStrip(const torch::Tensor& render, const torch::Tensor& image, const torch::Tensor& mask,
                              double background);
// Means over views; the masked figures over the views with a head.
ViewScores MeanScores(const std::vector<ViewScores>& scores);
// The mean time to draw one view, milliseconds, the first view (warming up)
// left out; 0 for fewer than two views.
double MeanRenderMs(const std::vector<ViewScores>& scores);
// One view's entry of eval.json's "views" (frame and camera with it) or, for
// a mean, its "mean" (`with_view` false).
nlohmann::json ScoresJson(const ViewScores& scores, bool with_view = true);
// The held-out views' mean scores (`views` of them) and the training views'
// masked PSNR into `summary`.
void SetSummaryScores(const ViewScores& held_out, int views, const ViewScores& training_views, TrainSummary* summary);

}  // namespace headforge
