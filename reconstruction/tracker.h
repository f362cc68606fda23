// 3DMM tracking: a Ceres fit over a whole sequence of the face model's shared
// identity, each frame's head motion and each frame's 53 blendshape weights,
// to the detected 68 landmarks of every view, through calibrated cameras.
#pragma once

#include <Eigen/Geometry>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/status.h"
#include "reconstruction/landmark_basis.h"
#include "reconstruction/tracking_costs.h"

namespace headforge {

// One camera's view of one frame.
struct TrackingView {
  int frame = 0;
  TrackingCamera camera;  // intrinsics and cam_from_head for this frame
  // Detected landmarks in pixels, or nothing where the face was not found.
  std::optional<std::array<Eigen::Vector2d, 68>> landmarks;
  // Per-landmark confidence in [0, 1] (0: ignore); all 1 when empty.
  std::vector<double> confidence;
  // This view's landmarks on the model when they depend on the direction it
  // sees the head from (ViewLandmarkBases); null: the sequence's basis.
  std::shared_ptr<const LandmarkBasis> basis;
  // The face mesh's 468 points in pixels (ingest's --face-mesh), fitted
  // against the mesh basis TrackSequence is given; empty: none.
  std::vector<Eigen::Vector2d> mesh;
};

struct TrackOptions {
  // Identity modes fitted (shared by the sequence), with a unit Gaussian
  // prior of this weight (pixels per standard deviation).
  int identity_modes = 20;
  double identity_prior = 2.0;
  // Sparsity of the blendshape weights: an L1-like prior costing this many
  // squared pixels per unit of weight (quadratic below `sparsity_scale`).
  double expression_sparsity = 30.0;
  double sparsity_scale = 0.05;
  // Temporal smoothness between consecutive frames: pixels per radian and per
  // metre of head motion, and per unit of blendshape weight.
  double rotation_smoothness = 100.0;
  double translation_smoothness = 300.0;
  double expression_smoothness = 3.0;
  // Per frame, its sample number in the capture (IngestedCapture::samples):
  // frames chosen far apart in time (ingest's --select) are linked as
  // weakly as the samples between them say. Empty: frame k is sample k.
  std::vector<int> samples;
  // Huber scale of the landmark residuals, pixels.
  double robust_scale_px = 2.0;
  // Weight of the jaw contour (landmarks 0-16), whose detector definition
  // slides along the cheek with the view.
  double contour_weight = 0.5;
  // A view whose camera is turned from the face by more than this (degrees)
  // leaves its jaw contour out, fading over the 10 degrees before it: there the
  // detector draws the contour along the silhouette, on another part of the
  // face than the frontal definition, and it pulls the jaw open. Where views
  // from the front are missing the contour of the others still counts at the
  // faded weight; 180 keeps every view's contour.
  double contour_max_yaw_deg = 20.0;
  // Weight of each of the face mesh's 468 points, against 1 for each of the
  // 68 landmarks, where TrackSequence is given the mesh's basis (the track
  // stage); its outline (MeshOvalPoints) weighs as the jaw contour does,
  // times this. 0 (the default) leaves the mesh out. On talking_static the
  // mesh at 0.4 fits the avatar's training views 1.3 dB better and its novel
  // views 4-6 dB better (docs/vision.md), but puts the head's rotation 1.84
  // deg off the truth against 1.33 deg (a constant tilt of the head frame
  // most of it), raises the 68 points' residual above the low-confidence
  // flag's 3 px on some frames, fits a multi-view rig worse, and triples
  // track's time.
  double mesh_weight = 0.0;
  // The cameras already carry the head's motion (head-pose calibration):
  // hold each frame's head motion at the identity.
  bool fixed_head = false;
  // One head motion for every frame (a rigid move of the head frame): the
  // cameras carry the head's motion from frame to frame, and the fit places
  // the head frame (head-pose cameras that features refined). Not with
  // fixed_head.
  bool one_head_motion = false;
  // Refine the focal length: one zoom-and-dolly factor on every camera's fx,
  // fy and distance along its axis (tracking_costs.h), within
  // [1/max_focal_change, max_focal_change]. Meant for one camera looking at
  // the head (head-pose cameras); only with the head's motion free.
  bool fit_focal = false;
  double max_focal_change = 3.0;
  // With fit_focal: a log-normal prior on the factor, centred at
  // `focal_prior_scale` (the prior's focal length over the cameras' current
  // one; 0: no prior) with `focal_prior_sigma` in log units (weighted as
  // residuals of robust_scale_px pixels); and whether to estimate the
  // factor's uncertainty (TrackResult::focal_log_sigma).
  double focal_prior_scale = 0.0;
  double focal_prior_sigma = 0.7;
  bool focal_uncertainty = false;
  // A frame that some camera sees within this yaw of frontal (degrees, with
  // the cameras' initial head pose) ignores its views beyond it.
  double max_fit_yaw_deg = 35.0;
  int max_iterations = 100;
  int threads = 1;
  // A frame is flagged low-confidence when its median residual exceeds this
  // (pixels), fewer than `min_landmarks` landmarks were seen, the head turns
  // more than `max_yaw_deg` from a camera, or its landmarks are nearly
  // collinear.
  double flag_residual_px = 3.0;
  int min_landmarks = 34;
  double max_yaw_deg = 60.0;

  bool Check(std::string* why) const;
};

struct TrackedFrame {
  int frame = 0;
  // The head's motion in the head frame: X' = rotation * X + translation.
  Eigen::Isometry3d head_motion = Eigen::Isometry3d::Identity();
  Eigen::VectorXd expression;   // [E] in [0, 1]
  double residual_px = 0;       // median landmark residual over its views (0 when interpolated)
  int landmarks = 0;            // landmarks observed over its views
  bool interpolated = false;    // no landmarks: values from the neighbouring frames
  bool low_confidence = false;
  std::string why;              // reasons for the flag
};

struct TrackResult {
  Eigen::VectorXd identity;  // [K]
  double focal_scale = 1.0;  // factor on the cameras' focal lengths (1 unless fit_focal)
  double focal_log_sigma = 0;  // its standard deviation in log units (TrackOptions::focal_uncertainty; else 0)
  std::vector<TrackedFrame> frames;
  double median_residual_px = 0;
  // Views dropped after a first fit because their landmarks disagreed with
  // the rest of their frame (median residual over 3x the overall median).
  int dropped_views = 0;
  int iterations = 0;
  double seconds = 0;
  std::string solver_report;  // Ceres' one-line summary
};

// Frames are 0 .. num_frames-1; `views` may hold several views per frame
// (multi-view frames are fitted jointly) and none for some. `mesh_basis`
// (468 points: the face mesh's embedding) fits the views' mesh points too;
// null leaves them out.
Status TrackSequence(const LandmarkBasis& basis, const std::vector<TrackingView>& views,
                     int num_frames, const TrackOptions& options, TrackResult* result,
                     const LandmarkBasis* mesh_basis = nullptr);

// The head rotation about the camera's vertical axis (degrees): 0 facing the
// camera.
double YawFromCamera(const TrackingCamera& camera, const Eigen::Isometry3d& head_motion);

}  // namespace headforge
