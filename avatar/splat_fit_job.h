// Static scene fitting for callers that do not use LibTorch (the command
// line): images, cameras and starting points in, the fitted Gaussians and the
// held-out evaluation out, as plain arrays and OpenCV images.
#pragma once

#include <opencv2/core.hpp>

#include <functional>
#include <string>
#include <vector>

#include "avatar/train/splat_fit_options.h"
#include "core/mesh_renderer.h"
#include "core/progress.h"
#include "core/stats_log.h"
#include "core/status.h"

namespace headforge {

struct SplatFitView {
  cv::Mat image;          // CV_8UC3 BGR
  PinholeCamera camera;   // of this image
  std::string name;
};

// Starting Gaussians: position, colour and size each.
struct SplatFitPoints {
  std::vector<float> positions;  // [N, 3] world, metres
  std::vector<float> colours;    // [N, 3] RGB in [0, 1]
  std::vector<float> sizes;      // [N] metres
};

struct SplatFitOutput {
  int steps = 0;
  int resumed_from = 0;  // the checkpoint's step the fit continued from (0: started afresh)
  double seconds = 0;
  double test_psnr = 0, test_ssim = 0;
  std::vector<double> view_psnr;        // per held-out view
  std::vector<cv::Mat> test_renders;    // CV_8UC3 BGR per held-out view
  // The fitted Gaussians, N rows each.
  int64_t size = 0;
  std::vector<float> means;           // [N, 3]
  std::vector<float> colours;         // [N, 3] RGB in [0, 1]
  std::vector<float> opacity_logits;  // [N]
  std::vector<float> log_scales;      // [N, 3]
  std::vector<float> rotations;       // [N, 4] unit (w, x, y, z)
};

// Whether `device` ("cpu", "cuda", "cuda:N") can run a fit here; a clear error
// if not (unknown name, no CUDA in this build's LibTorch, no such GPU).
Status CheckSplatFitDevice(const std::string& device);

// `stats` receives one JSON object per line (stats.jsonl). Checkpoints and
// resuming as FitSplats (train/splat_fit.h) does them.
Status RunSplatFit(const SplatFitOptions& options, const std::vector<SplatFitView>& train,
                   const std::vector<SplatFitView>& test, const SplatFitPoints& init, StatsLog* stats,
                   Progress* progress, SplatFitOutput* output);

}  // namespace headforge
