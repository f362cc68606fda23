// Whether a camera moves: how the background (off the head) of its ingested
// frames moves between frames a quarter of the sequence apart. calibrate's
// auto mode chooses head-pose or COLMAP cameras by it, and ingest's auto crop
// keeps a moving camera's frames whole.
#pragma once

#include <string>

#include "capture/capture_io.h"
#include "core/status.h"

namespace headforge {

// Median background motion (pixels of the ingested frames) above which a camera moves.
inline constexpr double kMovingCameraPx = 1.5;

struct BackgroundMotion {
  double median_px = 0.0;  // median displacement of the features optical flow follows
  int followed = 0;        // features followed there and back
  // Median absolute change of the background's grey levels between the
  // frames (after removing a global offset): about 1 for a fixed camera under
  // compression noise; a camera that moved far over textured surroundings
  // changes it by ten or more, and its features are lost rather than followed.
  double change = 0.0;
  // A moving camera: followed features move more than `threshold_px`, or too
  // few are followed while the background changed.
  bool Moving(double threshold_px) const;
  std::string Describe() const;  // for the log and the stage summary
};
Status MeasureBackgroundMotion(const IngestedCapture& capture, const std::string& camera, BackgroundMotion* motion);

}  // namespace headforge
