// Fitting a static Gaussian scene to posed images: L1 + SSIM loss, Adam,
// densification through a DensifyStrategy, held-out evaluation, and one JSON
// line of statistics per log tick.
#pragma once

#include <torch/types.h>

#include <functional>
#include <string>
#include <vector>

#include "avatar/train/densify.h"
#include "avatar/splat/splat_camera.h"
#include "avatar/train/splat_fit_options.h"
#include "core/progress.h"
#include "core/stats_log.h"
#include "core/status.h"

namespace headforge {

struct PosedImage {
  SplatCamera camera;
  torch::Tensor image;  // [3, H, W] float RGB in [0, 1]
  std::string name;
};

// Starting points: positions, colours and a size each.
struct InitPoints {
  torch::Tensor positions;  // [N, 3] world, metres
  torch::Tensor colours;    // [N, 3] RGB in [0, 1]
  torch::Tensor sizes;      // [N] metres
};


struct SplatFitResult {
  GaussianParams params;  // on the CPU (after a fit that succeeded)
  int steps = 0;
  double train_seconds = 0;
  double test_psnr = 0, test_ssim = 0;  // means over the held-out views
  std::vector<double> view_psnr;        // per held-out view
  std::vector<torch::Tensor> test_renders;  // [3, H, W] per held-out view
  int resumed_from = 0;  // the checkpoint's step it continued from (0: started afresh)
};

// Parses `name` ("cpu", "cuda", "cuda:N") into a device that can run a fit
// here, or says why it cannot.
Status ParseSplatFitDevice(const std::string& name, torch::Device* device);

// `stats` receives one JSON object per line (loss curve, evaluations). With
// options.checkpoint_path, the fit saves its whole state there every
// options.checkpoint_every steps and when interrupted (SIGINT/SIGTERM inside
// an InterruptScope: it then returns Status::Interrupted), and a fit that
// finds a checkpoint there continues from it, `stats` cut back to the lines
// the checkpoint had seen: the result equals an uninterrupted fit's.
Status FitSplats(const SplatFitOptions& options, const std::vector<PosedImage>& train,
                 const std::vector<PosedImage>& test, const InitPoints& init, StatsLog* stats,
                 Progress* progress, SplatFitResult* result);

// Renders the fitted scene into `camera` ([3, H, W], no gradient).
torch::Tensor RenderFitted(const GaussianParams& params, const SplatCamera& camera,
                           const SplatOptions& options = {});

}  // namespace headforge
