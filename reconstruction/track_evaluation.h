// Tracking accuracy against a simulator's ground_truth.json: what `headforge
// bench track` reports and the track tests assert.
#pragma once

#include <map>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/camera_set.h"
#include "capture/capture_io.h"
#include "reconstruction/tracking_io.h"

namespace headforge {

struct TrackingErrors {
  int views = 0;               // registered views scored
  int dropped_views = 0;       // views the fit left out (tracking.json)
  double contour_weight = 0;   // the jaw contour's weight the fit used (tracking.json)
  double residual_px = 0;      // median landmark residual, source pixels
  double rotation_deg = 0;     // median error of each view's cam_from_head · head motion
  // The same after one constant rotation of the head frame (the one that best
  // maps the estimated head frame onto the true one): how well the head's
  // motion is followed, apart from where the head frame itself sits.
  double motion_deg = 0;
  Eigen::Vector3d constant_deg = Eigen::Vector3d::Zero();  // that rotation, axis × angle (x pitch, y yaw, z roll)
  std::map<std::string, double> mae;  // per blendshape asked for: mean absolute weight error over the frames
};

// Scores `tracking` (tracking.json) fitted with `cameras` (head frame) on
// `capture` against the simulator's `truth`. Every camera's registered views
// count toward the rotation; the blendshapes are scored on the first camera's
// frames.
Status EvaluateTracking(const TrackingFile& tracking, const CameraSet& cameras, const IngestedCapture& capture,
                        const nlohmann::json& truth, const std::vector<std::string>& blendshapes,
                        TrackingErrors* errors);

// The simulator's truth in a tracked workspace's terms, for the parts named:
// "cameras" (each camera's intrinsics in the ingested frames' pixels, and
// every view's pose at its instant, all views registered), "expression"
// (each frame's blendshape weights), "identity" (the subject's shape). The
// parts not named keep the tracked values. The head frame becomes the
// simulator's, which is the face model's own, as head-pose cameras and the
// tracked identity assume. An avatar trained on the result has the
// registration error taken out: what tracking costs it.
Status TruthAsTracked(const IngestedCapture& capture, const nlohmann::json& truth,
                      const std::set<std::string>& parts, CameraSet* cameras, TrackingFile* tracking);

}  // namespace headforge
