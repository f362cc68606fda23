// Camera accuracy against a simulator's ground_truth.json: what `headforge
// bench calibrate` reports and the tests assert.
#pragma once

#include <nlohmann/json.hpp>

#include "core/camera_set.h"
#include "calibration/similarity.h"
#include "capture/capture_io.h"

namespace headforge {

struct CameraErrors {
  int views = 0, registered = 0;
  double median_rotation_deg = 0, max_rotation_deg = 0;
  double median_centre_mm = 0, max_centre_mm = 0;
  double scale_error = 0;  // |s_align / s_true - 1|, when an alignment is given
  double focal_error = 0;  // |f / f_true - 1| of the first camera
};

// Structure-from-motion cameras (frame "world"): errors after the similarity
// that best maps the estimated camera centres onto the true ones (the
// reconstruction's own accuracy); with `head_from_world`, the scale error of
// that alignment against the true scale.
Status EvaluateWorldCameras(const CameraSet& cameras, const IngestedCapture& capture, const nlohmann::json& truth,
                            const Sim3* head_from_world, CameraErrors* errors);

// Head-frame cameras (head-pose mode, or after align): rotation and centre
// errors of cam_from_head against the truth, with no further alignment.
Status EvaluateHeadCameras(const CameraSet& cameras, const IngestedCapture& capture, const nlohmann::json& truth,
                           CameraErrors* errors);

}  // namespace headforge
