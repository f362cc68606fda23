// A foreground mask of the head (face, hair, ears, neck) for one frame, by
// GrabCut (Rother et al. 2004) seeded from the landmarks: their hull is sure
// foreground, a head-shaped region around it probable foreground, and what lies
// well outside it sure background.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

#include "capture/landmarks.h"

namespace headforge {

struct HeadMaskOptions {
  // Side of the square GrabCut works at (pixels); the mask is upsampled after.
  int work_size = 160;
  // GrabCut iterations.
  int iterations = 3;
  // GrabCut runs from this many seeds of its colour models' k-means, and the
  // mask that reaches least along the frame's top and sides, then the
  // smallest, is kept: the result swings with that draw, and a failed draw
  // takes part of the backdrop for the head (on simulated talking_static's
  // textured backdrop, 25 of 125 frames with one draw, none with four).
  int attempts = 4;
};

// 8-bit mask, 255 on the head, the size of `bgr`. Deterministic for a `seed`.
cv::Mat HeadMask(const cv::Mat& bgr, const Landmarks68& landmarks, const HeadMaskOptions& options,
                 uint64_t seed);

// The seed regions alone (GC_BGD, GC_PR_BGD, GC_PR_FGD, GC_FGD labels).
cv::Mat HeadMaskSeeds(cv::Size size, const Landmarks68& landmarks);

}  // namespace headforge
