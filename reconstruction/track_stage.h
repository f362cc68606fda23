// The track stage: reads ingest's landmarks and the head-frame cameras of a
// workspace, runs TrackSequence, and writes tracking.json, optional per-frame
// meshes and an overlay video of the fitted mesh on the frames.
#pragma once

#include <string>

#include "calibration/calibrate.h"
#include "calibration/mesh_embedding.h"
#include "core/camera_set.h"
#include "capture/capture_io.h"
#include "core/face_model.h"
#include "core/options.h"
#include "core/progress.h"
#include "reconstruction/tracker.h"

namespace headforge {

struct TrackStageOptions {
  TrackOptions fit;
  // Where the detector's landmarks sit on the face model (JSON, see
  // calibration/landmark_embedding.h); empty: the shipped view grid when the
  // views of a frame see the head from directions more than
  // `grid_min_span_deg` apart in yaw (each view then uses the points as seen
  // from its side), else the shipped points for every view.
  std::string landmark_embedding;
  // Where the face mesh's 468 points sit on the model (mesh_embedding.h),
  // for frames where ingest found the mesh when fit.mesh_weight > 0.
  std::string mesh_embedding = DefaultMeshEmbedding();
  // Views of a frame this far apart in yaw (degrees) surround the head: they
  // take the view grid (above) and `multiview_contour_weight`.
  double grid_min_span_deg = 30.0;
  // The jaw contour's weight (instead of fit.contour_weight) when the views of
  // a frame see the head from more than `grid_min_span_deg` apart: each view
  // then draws the silhouette where its own side of the jaw turns away, and
  // the contour put the rig_8cam head frame 1-2 deg off in pitch (rotation
  // 2.0-2.2 deg at 0.5, 1.3-1.4 deg at 0.05).
  double multiview_contour_weight = 0.05;
  // The face mesh's weight (instead of fit.mesh_weight) when the views of a
  // frame surround the head (0: fit.mesh_weight stays). The 68-point
  // predictor reads a turned face as nearly frontal, the mesh network far
  // less: on the unlit dome_360 the tracked face in cam0 is 9.77 deg off the
  // truth at 0 and 2.29 deg at 0.4; on the lit rig_8cam 0.4 turns the head
  // 1.35 -> 1.21 deg off but mouthSmile_R's error 0.10 -> 0.23, so it is
  // not the default.
  double multiview_mesh_weight = 0.0;
  // With head-pose cameras (which carry each frame's head pose), refine that
  // pose together with the fitted shape and expressions; false holds it as
  // calibrated (on talking_static: blendshape errors 0.08-0.10 refined against
  // 0.10-0.12 held, head rotation 2.2 deg against 1.9 deg).
  bool refine_head_pose = true;
  // Each frame's head motion: "free" (fitted per frame), "still" (held at
  // rest: the cameras carry every change of view, for a head that holds
  // still while the camera goes round it) or "auto" (still for one camera
  // carried round the head, CameraSet::WalksRoundTheHead, where a frame's
  // single view cannot tell its head's turn from its camera's and the
  // detector's landmarks on the sides and the back are unreliable; free
  // otherwise, held by head-pose cameras unless refine_head_pose).
  std::string head_motion = "auto";
  bool overlay = true;   // overlay_<camera>.mp4
  bool meshes = false;   // meshes/<frame>.obj (fitted head, head frame)

  Status Check() const;
};

void AddTrackOptions(OptionSet* options, TrackStageOptions* track);

struct TrackSummary {
  int frames = 0, interpolated = 0, low_confidence = 0;
  int dropped_views = 0;  // views left out for disagreeing with the rest of their frame
  double median_residual_px = 0;
  double seconds = 0;
  bool fixed_head = false;
  std::vector<std::string> outputs;  // files written into the output folder
};

// `cameras` in the head frame: head-pose cameras (each frame's camera carries
// the head's motion) or align's cameras_head.json.
Status RunTrack(const TrackStageOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                const FaceModel& model, const fs::path& out_dir, Progress* progress, TrackSummary* summary);

struct HeadPoseRefinement {
  double focal_before = 0, focal_after = 0;  // pixels
  int rounds = 0;                            // fits run
  bool settled = false;                      // the last fit moved the focal length by less than min_change
  double median_residual_px = 0;             // landmark residual of the fit
  double seconds = 0;
  std::string solver_report;                 // Ceres' one-line summary
  double focal_log_sigma = 0;                // the last fit's standard deviation of ln(focal); 0: not computed
};

// Head-pose cameras refined with the whole face model. Against the mean
// face's landmarks alone the focal length is poorly determined: perspective
// across a face moves its landmarks by a few pixels, and a face deeper or
// flatter than the mean reads as a nearer or farther one. This fits the
// sequence as tracking does (shared identity, each frame's expression and
// head motion) with the focal length free, then folds the fitted focal length
// into the camera and each frame's head motion into its cam_from_head. The
// focal length lies in a long, shallow valley with the identity's depth: a
// fit stops in it, and a new fit started from the cameras it left (identity
// and expressions from zero again) goes further along, so fits are repeated
// until the focal length changes by less than `min_change` (relative) or
// `max_rounds` have run. Where the head barely turns the valley has no
// floor; `prior_focal` (pixels; 0: none) holds the focal length near an
// ordinary lens's there, with options.focal_prior_sigma (TrackOptions).
// `fit_focal` false holds the focal length as the cameras have it (one
// given by the user): the poses alone move.
Status RefineHeadPoseCameras(const FaceModel& model, const IngestedCapture& capture, const TrackOptions& options,
                             const std::string& landmark_embedding, int max_rounds, double min_change,
                             double prior_focal, bool fit_focal, CameraSet* cameras, HeadPoseRefinement* result,
                             const std::string& mesh_embedding = "");

// The calibrate stage's last step for head-pose cameras (calibrate's result
// when it chose head-pose): RefineHeadPoseCameras as `calibrate.head_pose.refine`
// asks, its focal length and residual reported in `summary`. Leaves other
// cameras alone, and a focal length the user gave (the poses are refined at
// it); `applied` (optional) says whether it changed the cameras.
Status RefineHeadPoseStep(const CalibrateOptions& calibrate, const IngestedCapture& capture, const FaceModel& model,
                          int threads, Progress* progress, CameraSet* cameras, CalibrateSummary* summary,
                          bool* applied = nullptr);

}  // namespace headforge
