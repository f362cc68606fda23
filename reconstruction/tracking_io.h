// tracking.json: what the track stage fitted, as later stages (train, export,
// the benches) read it back.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/face_model.h"
#include "core/fs.h"
#include "core/status.h"
#include "reconstruction/tracker.h"

namespace headforge {

struct TrackingFile {
  static constexpr int kVersion = 1;  // ReadTracking refuses another

  std::string face_model;                     // the model file fitted
  int identity_modes = 0;
  Eigen::VectorXd identity;                   // [identity_modes] in standard deviations
  std::vector<std::string> expression_names;  // the model's blendshapes, in its order
  bool head_held_by_cameras = false;          // the cameras carry the head's motion (head-pose cameras, or a still head)
  double median_residual_px = 0;
  int dropped_views = 0;
  std::string landmark_embedding;             // the embedding file used
  bool view_dependent_landmarks = false;
  double contour_weight = 0;                  // the jaw contour's weight the fit used
  std::string solver;                         // Ceres' one-line report
  double seconds = 0;
  // One per frame, in frame order; each expression in expression_names' order.
  std::vector<TrackedFrame> frames;

  // The frame record of output frame `index`, or nullptr.
  const TrackedFrame* Find(int index) const;
};

Status WriteTracking(const TrackingFile& tracking, const fs::path& path);
// Reads tracking.json, checking its version and that every frame carries one
// weight per expression name.
Status ReadTracking(const fs::path& path, TrackingFile* tracking);

// What the stages after track read of a workspace: the ingested capture, the
// head-frame cameras and tracking.json, checked to agree with each other and
// with `model` (the face model tracking was fitted with).
Status ReadTrackedWorkspace(const fs::path& workspace, const FaceModel& model, IngestedCapture* capture,
                            CameraSet* cameras, TrackingFile* tracking);

// A frame of `camera` and its head mask, with the lens's distortion removed.
Status ReadUndistortedFrame(const IngestedCapture& capture, const std::string& camera, const CameraIntrinsics& lens,
                            int frame, cv::Mat* image, cv::Mat* mask);

}  // namespace headforge
