// `headforge ingest`, `calibrate`, `align` and `run`.
#include <cstdio>

#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "pipelines/commands.h"
#include "pipelines/stages.h"

namespace headforge {
namespace {

// Options of the stages after ingest, shared by their commands and by `run`.
struct LaterStages {
  CalibrateOptions calibrate;
  AlignOptions align;
  TrackStageOptions track;
  std::string face_model;

  void Add(OptionSet* o) {
    AddCalibrateOptions(o, &calibrate);
    AddAlignOptions(o, &align);
    AddTrackOptions(o, &track);
    o->Add("face_model", &face_model,
           "Face model (Basel-layout HDF5); default DATA/ict_facekit/ict_face_model.h5.", "face-model",
           OptionSet::Effect::kRuntime);
  }
  void Resolve(const CommonOptions& common) {
    if (face_model.empty()) face_model = (fs::path(common.data_dir) / "ict_facekit" / "ict_face_model.h5").string();
  }
};

int Threads(const CommonOptions& common) { return common.threads > 0 ? common.threads : HardwareThreads(); }

// Opens the workspace for writing, reporting failures.
int OpenWorkspace(const CommonOptions& common, std::unique_ptr<Workspace>* workspace) {
  if (Status s = Workspace::Open(common.workspace, Workspace::Mode::kReadWrite, workspace); !s.ok())
    return ReportFailure(s);
  return -1;
}

}  // namespace

int IngestCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  IngestOptions ingest;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  AddIngestOptions(&options, &ingest);
  const std::string usage = "headforge ingest --video FILE|DIR... --workspace DIR [options]";
  const int parsed = ParseOrExit(
      &options, args, usage,
      "Samples frames from one video or image folder per camera, drops blurred frames, detects\n"
      "the face and its 68 landmarks, crops and resizes around the head, and makes a head mask.\n"
      "Writes frames/, masks/, landmarks.json and capture.json into the workspace.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  ResolveIngestDefaults(common.data_dir, &ingest);
  if (Status s = ingest.Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenWorkspace(common, &workspace); code >= 0) return code;
  StderrProgress progress;
  if (Status s = RunIngestStage(workspace.get(), ingest, options, Threads(common), &progress); !s.ok())
    return ReportFailure(s);
  return kExitOk;
}

int CalibrateCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  LaterStages stages;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  stages.Add(&options);
  const int parsed = ParseOrExit(
      &options, args, "headforge calibrate --workspace DIR [--mode auto|colmap|head-pose|rig] [options]",
      "Estimates the cameras of the ingested frames: COLMAP structure from motion for a moving\n"
      "camera or several cameras, head-pose cameras for a fixed camera, or a rig file.\n"
      "Writes cameras.json (and colmap/ with the COLMAP model when SfM ran).");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  stages.Resolve(common);
  if (Status s = stages.calibrate.Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenWorkspace(common, &workspace); code >= 0) return code;
  StderrProgress progress;
  if (Status s = RunCalibrateStage(workspace.get(), stages.calibrate, stages.face_model, options, Threads(common), &progress);
      !s.ok())
    return ReportFailure(s);
  return kExitOk;
}

int AlignCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  LaterStages stages;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  stages.Add(&options);
  const int parsed = ParseOrExit(
      &options, args, "headforge align --workspace DIR [options]",
      "Aligns the reconstruction to the face model's metric head frame: triangulates the\n"
      "landmarks, fits a similarity by Umeyama's method in RANSAC, reports residuals in mm.\n"
      "Writes alignment.json (head_from_world) and cameras_head.json.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  stages.Resolve(common);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenWorkspace(common, &workspace); code >= 0) return code;
  if (Status s = RunAlignStage(workspace.get(), stages.align, stages.face_model, options); !s.ok())
    return ReportFailure(s);
  return kExitOk;
}

int TrackCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  LaterStages stages;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  stages.Add(&options);
  const int parsed = ParseOrExit(
      &options, args, "headforge track --workspace DIR [options]",
      "Fits the face model to the detected landmarks over the whole sequence with Ceres: a\n"
      "shared identity, each frame's head motion (held by head-pose cameras) and 53 blendshape\n"
      "weights in [0, 1]. Writes tracking.json and overlay_<camera>.mp4 (the fitted mesh on\n"
      "the frames).");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  stages.Resolve(common);
  stages.track.fit.threads = Threads(common);
  if (Status s = stages.track.Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenWorkspace(common, &workspace); code >= 0) return code;
  StderrProgress progress;
  if (Status s = RunTrackStage(workspace.get(), stages.track, stages.face_model, options, &progress); !s.ok())
    return ReportFailure(s);
  return kExitOk;
}

int RunCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  IngestOptions ingest;
  LaterStages stages;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  AddIngestOptions(&options, &ingest);
  stages.Add(&options);
  const std::string usage = "headforge run --video FILE|DIR... --workspace DIR [options]";
  const int parsed = ParseOrExit(
      &options, args, usage,
      "Runs the pipeline's stages in order into one workspace: ingest, calibrate, align and\n"
      "track (train and export follow as they become available). A stage whose inputs and\n"
      "options are unchanged is skipped; a failed or interrupted one is redone.\n"
      "Options of every stage are accepted, by their short flag or their dotted key.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  ResolveIngestDefaults(common.data_dir, &ingest);
  stages.Resolve(common);
  stages.track.fit.threads = Threads(common);
  for (const Status& s : {ingest.Check(), stages.calibrate.Check(), stages.align.Check(), stages.track.Check()})
    if (!s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenWorkspace(common, &workspace); code >= 0) return code;
  StderrProgress progress;
  if (Status s = RunIngestStage(workspace.get(), ingest, options, Threads(common), &progress); !s.ok())
    return ReportFailure(s);
  if (Status s = RunCalibrateStage(workspace.get(), stages.calibrate, stages.face_model, options, Threads(common), &progress);
      !s.ok())
    return ReportFailure(s);
  if (Status s = RunAlignStage(workspace.get(), stages.align, stages.face_model, options); !s.ok())
    return ReportFailure(s);
  if (Status s = RunTrackStage(workspace.get(), stages.track, stages.face_model, options, &progress); !s.ok())
    return ReportFailure(s);
  HF_LOG(Info) << "run: track is the last stage available in this version; results are in " << common.workspace
               << " (headforge status " << common.workspace << ")";
  return kExitOk;
}

}  // namespace headforge
