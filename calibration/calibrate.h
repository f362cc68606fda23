// The calibrate stage: cameras for the ingested frames, by the method that
// suits the capture (DESIGN.md, "Capture modes").
//   colmap     structure from motion (moving camera, several cameras)
//   head-pose  a fixed camera: head poses from landmarks with a shared focal length
//   rig        intrinsics and extrinsics imported from a file
//   auto       head-pose for one video whose background does not move, else
//              colmap; falls back to head-pose when COLMAP registers too few frames
#pragma once

#include <string>

#include "core/camera_set.h"
#include "calibration/landmark_embedding.h"
#include "calibration/colmap_runner.h"
#include "calibration/head_pose.h"
#include "capture/background_motion.h"
#include "capture/capture_io.h"
#include "core/face_model.h"
#include "core/options.h"
#include "core/progress.h"

namespace headforge {

struct CalibrateOptions {
  std::string mode = "auto";
  ColmapOptions colmap;
  HeadPoseOptions head_pose;
  // rig: a JSON file (docs/calibration.md) or a COLMAP text model folder.
  std::string rig;
  // Fewest registered frames, as a fraction of those given to COLMAP.
  double min_registered = 0.5;
  // Median background motion (pixels) above which a single video counts as a moving camera.
  double motion_threshold_px = kMovingCameraPx;
  // The detector's landmarks on the model (landmark_embedding.h); "" for the model's vertices.
  std::string landmark_embedding = DefaultLandmarkEmbedding();
  // Several cameras: "auto" (fixed when no camera's background moves), "yes", "no".
  std::string static_rig = "auto";
  Status Check() const;
};

void AddCalibrateOptions(OptionSet* options, CalibrateOptions* calibrate);

struct CalibrateSummary {
  std::string mode;       // the mode used
  std::string reason;     // why (auto mode), and any fallback
  int registered = 0, total = 0;
  double reprojection_px = 0.0;  // median landmark (head-pose) or mean SfM (colmap) reprojection error
  double reprojection_source_px = 0.0;  // the same in source-video pixels (head-pose)
  double focal = 0.0;     // head-pose: estimated focal length (frame pixels)
  double focal_log_sigma = 0.0;  // head-pose: its standard deviation in log units (0: given, or not computed)
  // colmap: registered after sequential matching alone when keyframes were
  // mapped (ColmapOptions::keyframe_step) or every pair was matched after it
  // (ColmapOptions::exhaustive_fallback_max); -1 otherwise.
  int sequential_registered = -1;
  int keyframe_step = 0;  // colmap: keyframes mapped, one image in this many (0: none)
  // colmap: pairs of revisited views matched after the first model (ColmapOptions::revisit_angle_deg).
  int revisit_pairs = 0;
  std::string OneLine() const;
};

// Calibrates into `out_dir` (cameras.json, colmap/ when SfM ran).
Status RunCalibrate(const CalibrateOptions& options, const IngestedCapture& capture, const FaceModel& model,
                    const fs::path& out_dir, Progress* progress, CameraSet* cameras, CalibrateSummary* summary);

// " (+-5.1%)" for a standard deviation of ln(focal) of 0.05; "" for 0.
std::string FocalUncertaintyText(double log_sigma);

// The focal length (frame pixels) at the centre of the head-pose prior:
// options.prior_fov_deg over the capture's first camera, through its crop;
// 0 when the prior is off or the capture has no camera.
double HeadPosePriorFocal(const HeadPoseOptions& options, const IngestedCapture& capture);

// Reads a rig file (JSON, or a COLMAP text model folder) into cameras for the
// ingested views; intrinsics given in source pixels are mapped through ingest's crop.
Status ImportRig(const std::string& path, const IngestedCapture& capture, CameraSet* cameras);

}  // namespace headforge
