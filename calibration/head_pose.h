// Cameras for a fixed camera watching a moving head: the head pose in every
// frame from its 68 landmarks, by PnP against the face model's landmark
// vertices, then one Ceres problem over the whole sequence with a shared focal
// length, a robust loss and temporal smoothness. The result is cam_from_head
// per frame: the head frame (the face model's) serves as the world.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "capture/landmarks.h"
#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

struct HeadPoseOptions {
  double focal = 0.0;            // pixels; 0 estimates it over the sequence
  // The source video's horizontal field of view in degrees, where the user
  // knows the lens (0: unknown); sets `focal` through the crop. Not with focal.
  double fov_deg = 0.0;
  // A prior on an estimated focal length toward ordinary lenses: log-normal
  // round a horizontal field of view of `prior_fov_deg` over the source video
  // (60: phones and webcams), `prior_sigma` in log units (0.7: a factor of 2
  // either way, about 32 to 98 degrees). Landmarks of a head that turns
  // decide the focal length alone; where the head barely turns they leave it
  // free and the prior holds it. prior_sigma 0: no prior.
  double prior_fov_deg = 60.0;
  double prior_sigma = 0.7;
  // The prior's centre in frame pixels (FocalFromFov through ingest's crop),
  // set by the caller; 0: no prior.
  double prior_focal = 0.0;
  double robust_px = 3.0;        // Huber loss scale on landmark residuals
  double jaw_weight = 0.3;       // weight of the jaw contour (0-16): detectors follow the silhouette
  double smoothness = 1.0;       // weight of the temporal smoothness term (0: none)
  int max_iterations = 100;
  // After the fit to the mean face's landmarks: "face-model" refines the focal
  // length and the poses by fitting the face model's identity and each frame's
  // expression as well (done by the calibrate stage, which has the tracker;
  // skipped when `focal` is given); "off" keeps the fit to the mean face.
  std::string refine = "face-model";
  // After that refinement: the poses refined by features tracked on the
  // head's rigid part (feature_poses.h). Not with refine "off".
  bool features = true;
  int refine_rounds = 6;  // fits at most, until the focal length changes by less than 1%
  // The face mesh's 468 points (where ingest found them) in that refinement,
  // each at this weight against 1 for each of the 68 landmarks; 0 leaves the
  // mesh out. Not a command-line option: on talking_static the mesh pulls the
  // focal length 26-40 % long (bench calibrate --head-pose-mesh-weight).
  double refine_mesh_weight = 0.0;
  // The 68 head-frame points the detector's landmarks stand for (see
  // landmark_embedding.h); empty: the model's landmark vertices.
  std::vector<Eigen::Vector3d> landmark_points;
  Status Check() const;
  // True when the focal length is given (focal or fov_deg), not estimated.
  bool FocalGiven() const { return focal > 0 || fov_deg > 0; }
};

// The focal length in frame pixels of a lens with horizontal field of view
// `fov_deg` over a source `source_width` pixels wide, cropped and scaled by
// `crop_scale` (frame pixels per source pixel).
double FocalFromFov(double fov_deg, int source_width, double crop_scale);

struct HeadPoseResult {
  double focal = 0.0;
  // The standard deviation of ln(focal) (0.05: about 5 %) from the fit's
  // covariance; 0 when the focal length was given.
  double focal_log_sigma = 0.0;
  std::vector<Eigen::Isometry3d> cam_from_head;  // per frame
  std::vector<bool> observed;                    // frame had landmarks (others are interpolated)
  std::vector<double> rms_px;                    // per observed frame
  double median_px = 0.0;
  std::string message;
};

// `landmarks[i]` holds frame i's landmarks (frame pixels) or nothing;
// `principal` is the principal point in frame pixels.
Status EstimateHeadPoseCameras(const FaceModel& model, const std::vector<std::optional<Landmarks68>>& landmarks,
                               int width, int height, const Eigen::Vector2d& principal,
                               const HeadPoseOptions& options, HeadPoseResult* result);

}  // namespace headforge
