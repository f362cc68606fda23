// Which face ingest follows through a camera's frames: detections linked
// from frame to frame into tracks, the largest, most persistent one followed,
// and the same face come back after leaving the frame taken as itself.
#pragma once

#include <cstdint>
#include <vector>

#include "capture/face_detector.h"
#include "capture/landmarks.h"

namespace headforge {

struct FaceCandidate {
  FaceDetection detection;
  Landmarks68 landmarks;
  bool plausible = false;  // landmarks that look like a face (LandmarksArePlausible)
};

// One sampled frame of a camera as ingest's first pass saw it.
struct FrameAnalysis {
  int64_t source_index = -1;
  double sharpness = 0.0;
  std::vector<FaceCandidate> faces;
};

struct FaceChoice {
  std::vector<const FaceCandidate*> faces;  // per frame; nullptr where the followed face is not seen
  int others = 0;                           // other faces seen beside the followed one
  int followed_frames = 0, other_frames = 0;  // frames of the followed face; of the strongest other
  float followed_width = 0, other_width = 0;  // their median landmark widths, source px
};

// One camera's face in each of `frames` (in time order). Faces are linked
// from frame to frame into tracks (a plausible face overlapping a track's
// last box, IoU over 0.2, within 10 frames, continues it); the track with the
// most detection weight (score x the square root of the landmarks' box area,
// summed over its frames) is followed. Tracks that never share a frame with
// it and whose faces are within 1.5x its width are the same face come back
// elsewhere; the others of three frames or more are counted as other faces.
FaceChoice SelectFaces(const std::vector<const FrameAnalysis*>& frames);

}  // namespace headforge
