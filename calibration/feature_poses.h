// The head pose of every frame of a fixed camera refined by the texture of
// the head's rigid part: SIFT features on the forehead up to the hairline,
// the brows, the nose and the upper cheeks (without the eyes, the mouth and
// the jaw),
// matched between frames a few to some tens of frames apart, chained into
// tracks, and bundle-adjusted with one pose per frame while the 3D points ride
// the head. Landmarks place the head to about a degree per frame (a detector's
// points move a pixel or two from frame to frame); hundreds of features seen
// in many frames pin the head's motion between frames much closer. The
// adjusted poses are then moved together, by one rigid move of the head
// frame, back onto the starting ones on average: where the head frame sits
// is the landmarks' to say.
#pragma once

#include <string>

#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/status.h"

namespace headforge {

struct FeaturePoseOptions {
  double contrast_threshold = 0.003;  // SIFT's; skin's faint texture needs a low one
  double ratio = 0.8;                 // Lowe's ratio test
  double ransac_px = 1.5;             // the fundamental matrix's inlier distance between two frames
  int max_offset = 32;                // frames matched at offsets 1, 2, 4, ... up to this
  int min_track = 3;                  // frames a feature must be seen in
  double robust_px = 1.0;             // Huber scale of the reprojection residuals
  // A weak pull toward each frame's starting pose (a standard deviation in
  // degrees and in millimetres), for frames the features barely see; the
  // head frame is then moved back onto the starting poses on average. A
  // stronger pull keeps the landmarks' errors: on the simulated head_turn
  // (+-40 deg) 2 deg and 5 mm leave the motion 1.85 deg off, 30 deg and
  // 100 mm 0.81 deg (talking_static: 0.30 and 0.25 deg).
  double prior_rotation_deg = 30.0;
  double prior_translation_mm = 100.0;
  int min_frame_observations = 12;    // fewer: the frame keeps its starting pose
  int max_iterations = 50;
  // The poses are left as they were with fewer points than this, or when the
  // adjusted sightings' median reprojection exceeds max_median_px.
  int min_tracks = 50;
  double max_median_px = 1.0;
  int threads = 0;                    // 0: every hardware thread
  Status Check() const;
};

struct FeaturePoseStats {
  int frames = 0;          // frames with landmarks, searched for features
  int frames_moved = 0;    // frames whose pose the features refined
  int tracks = 0;          // 3D points adjusted
  int observations = 0;    // their sightings
  double median_px_before = 0, median_px_after = 0;  // reprojection of the sightings
  double median_change_deg = 0, median_change_mm = 0;  // how far the poses moved
  double seconds = 0;
  std::string left;  // why the poses were left as they were; empty when refined
  std::string Summary() const;
};

// Refines the registered views of `camera` in `cameras` (head-pose cameras:
// cam_from_world is cam_from_head, one fixed camera) in place. Frames without
// landmarks keep their poses. Fails when a frame cannot be read; too little
// texture to follow, or an adjustment that does not fit its sightings, leaves
// every pose as it was and says why in the stats.
Status RefineHeadPosesWithFeatures(const IngestedCapture& capture, const std::string& camera,
                                   const FeaturePoseOptions& options, CameraSet* cameras, FeaturePoseStats* stats);

}  // namespace headforge
