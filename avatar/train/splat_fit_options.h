// Options of static Gaussian scene fitting and of its densification
// strategy, kept free of LibTorch so that the command line can set them.
#pragma once

#include <cstdint>
#include <string>

#include "avatar/splat/splat_camera.h"

namespace headforge {

struct DefaultDensifyOptions {
  int start = 500;          // first step that may densify
  int stop = 15000;         // last one
  int interval = 100;       // steps between densifications
  int reset_every = 3000;   // steps between opacity resets (0: never)
  // Mean screen-space gradient (in units of half the image size) above which
  // a Gaussian is cloned or split.
  double grad_threshold = 0.0002;
  // Gaussians larger than this fraction of the scene extent are split, smaller
  // ones cloned.
  double split_scale = 0.01;
  double prune_opacity = 0.005;
  int64_t max_gaussians = 1000000;
  double scene_extent = 1.0;  // metres
  uint64_t seed = 0;
};

struct SplatFitOptions {
  int iterations = 30000;
  // Stop early when this much wall time has passed (0: no limit); the
  // evaluation after the last step is not counted.
  double max_minutes = 0;
  double ssim_weight = 0.2;  // loss = (1 - w) L1 + w (1 - SSIM)
  // Adam learning rates; the means' decays exponentially to 1% over the run
  // and scales with the scene extent.
  double lr_means = 1.6e-4, lr_quats = 1e-3, lr_scales = 5e-3, lr_opacity = 5e-2,
         lr_colours = 1e-2;
  double init_opacity = 0.1;
  int log_every = 100;    // steps between stats lines
  int eval_every = 2000;  // steps between held-out evaluations (0: only at the end)
  uint64_t seed = 0;
  // Where the fit runs: "cpu", or "cuda" / "cuda:N" in a build whose LibTorch
  // has CUDA. Results come back on the CPU either way.
  std::string device = "cpu";
  // Where the fit keeps its checkpoint ("": none); a fit that finds one there
  // continues from it.
  std::string checkpoint_path;
  int checkpoint_every = 500;  // steps between checkpoints (and one when interrupted)
  SplatOptions splat;
  DefaultDensifyOptions densify;

  bool Check(std::string* why) const;
};

}  // namespace headforge
