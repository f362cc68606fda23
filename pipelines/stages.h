// Each stage run inside a workspace: fingerprint, skip when up to date, run into
// staging, commit. Shared by the stage's own command and by `run`.
#pragma once

#include "calibration/align.h"
#include "calibration/calibrate.h"
#include "capture/ingest.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/workspace.h"
#include "reconstruction/track_stage.h"

namespace headforge {

// Runs (or skips) ingest; `options` is the parsed OptionSet whose "ingest"
// section is recorded as ingest.ini and enters the fingerprint.
Status RunIngestStage(Workspace* workspace, const IngestOptions& ingest, const OptionSet& options,
                      int threads, Progress* progress);

// Head-pose cameras (calibrate's result when it chose head-pose): the
// face-model refinement of their focal length and poses, as
// `calibrate.head_pose.refine` asks (reconstruction/track_stage.h). Leaves
// other cameras, and a given focal length, alone; `applied` (optional) says
// whether it changed the cameras.
Status RefineHeadPoseStep(const CalibrateOptions& calibrate, const IngestedCapture& capture, const FaceModel& model,
                          int threads, Progress* progress, CameraSet* cameras, CalibrateSummary* summary,
                          bool* applied = nullptr);

// Runs (or skips) calibrate on the workspace's ingest outputs.
Status RunCalibrateStage(Workspace* workspace, const CalibrateOptions& calibrate, const std::string& face_model,
                         const OptionSet& options, int threads, Progress* progress);

// Runs (or skips) align on the workspace's cameras.
Status RunAlignStage(Workspace* workspace, const AlignOptions& align, const std::string& face_model,
                     const OptionSet& options);

// Runs (or skips) track on the workspace's landmarks and head-frame cameras.
Status RunTrackStage(Workspace* workspace, const TrackStageOptions& track, const std::string& face_model,
                     const OptionSet& options, Progress* progress);

}  // namespace headforge
