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
};

// 8-bit mask, 255 on the head, the size of `bgr`. Deterministic for a `seed`.
cv::Mat HeadMask(const cv::Mat& bgr, const Landmarks68& landmarks, const HeadMaskOptions& options,
                 uint64_t seed);

// The seed regions alone (GC_BGD, GC_PR_BGD, GC_PR_FGD, GC_FGD labels).
cv::Mat HeadMaskSeeds(cv::Size size, const Landmarks68& landmarks);

}  // namespace headforge
