#include "pipelines/stages.h"

#include <cstring>

#include "calibration/colmap_runner.h"
#include "core/hash.h"
#include "core/log.h"
#include "core/parallel.h"

namespace headforge {

Status RunIngestStage(Workspace* workspace, const IngestOptions& ingest, const OptionSet& options,
                      int threads, Progress* progress) {
  HF_RETURN_IF_ERROR(ingest.Check());
  std::string fingerprint;
  HF_RETURN_IF_ERROR(IngestFingerprint(ingest, options.ToIni("ingest", true), &fingerprint)
                         .WithContext("ingest"));
  bool skipped = false;
  return RunStage(
      workspace, "ingest", fingerprint, options.ToIni("ingest"),
      [&](const fs::path& staging, StageResult* result) {
        IngestSummary summary;
        HF_RETURN_IF_ERROR(RunIngest(ingest, staging, threads, progress, &summary));
        result->outputs = {"frames", "masks", "landmarks.json", "capture.json"};
        result->message = summary.OneLine();
        HF_LOG(Info) << "ingest: " << result->message;
        return Status::Ok();
      },
      &skipped);
}

namespace {

// The fingerprint of a stage that reads `upstream` stages and the face model.
Status ChainedFingerprint(const Workspace& workspace, const std::string& stage, const std::vector<std::string>& upstream,
                          const std::string& options_ini, const std::string& face_model, std::string* fingerprint) {
  Hasher h;
  h.Add(stage + "-1").Add(options_ini);
  for (const auto& name : upstream) {
    const StageRecord* r = workspace.Find(name);
    if (!r || r->status != StageStatus::kDone)
      return Status::InvalidArgument(stage + " needs the " + name + " stage first (headforge " + name + " or headforge run)");
    h.Add(r->fingerprint);
  }
  HF_RETURN_IF_ERROR(h.AddFileStamp(face_model).WithContext("face model"));
  *fingerprint = h.Hex();
  return Status::Ok();
}

}  // namespace

Status RefineHeadPoseStep(const CalibrateOptions& calibrate, const IngestedCapture& capture, const FaceModel& model,
                          int threads, Progress* progress, CameraSet* cameras, CalibrateSummary* summary,
                          bool* applied) {
  if (applied) *applied = false;
  if (summary->mode != "head-pose" || calibrate.head_pose.refine != "face-model" || calibrate.head_pose.focal > 0)
    return Status::Ok();
  TrackOptions fit;
  fit.threads = threads > 0 ? threads : HardwareThreads();
  progress->Start("calibrate: refining with the face model", 0);
  HeadPoseRefinement refined;
  HF_RETURN_IF_ERROR(RefineHeadPoseCameras(model, capture, fit, calibrate.landmark_embedding,
                                           calibrate.head_pose.refine_rounds, 0.01, cameras, &refined));
  progress->Finish();
  if (!refined.settled)
    HF_LOG(Warning) << "calibrate: the focal length was still moving after " << refined.rounds
                    << " rounds of the face-model refinement (--head-pose-refine-rounds)";
  HF_LOG(Info) << "calibrate: the face model's identity and expressions move the focal length from "
               << refined.focal_before << " to " << refined.focal_after << " px in " << refined.rounds
               << " round(s) (landmark residual " << refined.median_residual_px << " px, " << refined.seconds << " s)";
  summary->focal = refined.focal_after;
  summary->reprojection_px = refined.median_residual_px;
  if (!capture.cameras.empty() && capture.cameras[0].crop_scale > 0)
    summary->reprojection_source_px = refined.median_residual_px / capture.cameras[0].crop_scale;
  summary->reason += std::string(summary->reason.empty() ? "" : "; ") + "refined with the face model from focal " +
                     std::to_string(static_cast<int>(std::lround(refined.focal_before))) + " px";
  if (applied) *applied = true;
  return Status::Ok();
}

Status RunCalibrateStage(Workspace* workspace, const CalibrateOptions& calibrate, const std::string& face_model,
                         const OptionSet& options, int threads, Progress* progress) {
  HF_RETURN_IF_ERROR(calibrate.Check());
  std::string fingerprint;
  HF_RETURN_IF_ERROR(ChainedFingerprint(*workspace, "calibrate", {"ingest"}, options.ToIni("calibrate", true),
                                        face_model, &fingerprint));
  bool skipped = false;
  return RunStage(
      workspace, "calibrate", fingerprint, options.ToIni("calibrate"),
      [&](const fs::path& staging, StageResult* result) {
        IngestedCapture capture;
        HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace->root(), &capture));
        FaceModel model;
        HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
        CalibrateOptions effective = calibrate;
        effective.colmap.threads = threads;
        CameraSet cameras;
        CalibrateSummary summary;
        HF_RETURN_IF_ERROR(RunCalibrate(effective, capture, model, staging, progress, &cameras, &summary));
        bool refined = false;
        HF_RETURN_IF_ERROR(
            RefineHeadPoseStep(effective, capture, model, threads, progress, &cameras, &summary, &refined));
        if (refined) HF_RETURN_IF_ERROR(cameras.Write(staging / "cameras.json"));
        result->outputs = {"cameras.json"};
        if (fs::exists(staging / "colmap")) result->outputs.push_back("colmap");
        result->message = summary.OneLine();
        HF_LOG(Info) << "calibrate: " << result->message;
        return Status::Ok();
      },
      &skipped);
}

Status RunAlignStage(Workspace* workspace, const AlignOptions& align, const std::string& face_model,
                     const OptionSet& options) {
  HF_RETURN_IF_ERROR(align.Check());
  std::string fingerprint;
  HF_RETURN_IF_ERROR(ChainedFingerprint(*workspace, "align", {"ingest", "calibrate"}, options.ToIni("align", true),
                                        face_model, &fingerprint));
  bool skipped = false;
  return RunStage(
      workspace, "align", fingerprint, options.ToIni("align"),
      [&](const fs::path& staging, StageResult* result) {
        IngestedCapture capture;
        HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace->root(), &capture));
        CameraSet cameras;
        HF_RETURN_IF_ERROR(CameraSet::Read(workspace->Path("cameras.json"), &cameras));
        FaceModel model;
        HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
        AlignResult aligned;
        HF_RETURN_IF_ERROR(RunAlign(align, capture, cameras, model, &aligned));
        HF_RETURN_IF_ERROR(WriteAlignment(aligned, staging / "alignment.json"));
        HF_RETURN_IF_ERROR(aligned.cameras.Write(staging / "cameras_head.json"));
        result->outputs = {"alignment.json", "cameras_head.json"};
        char refined[80] = "";
        if (aligned.reprojection_median_px > 0)
          std::snprintf(refined, sizeof(refined), ", landmark reprojection %.1f px", aligned.reprojection_median_px);
        char views[160] = "";
        if (aligned.views_used > 0) std::snprintf(views, sizeof(views), ", rotation from %d views", aligned.views_used);
        if (aligned.surface_points > 0)
          std::snprintf(views + std::strlen(views), sizeof(views) - std::strlen(views),
                        ", surface fit on %d points on the face (turned %.2f deg, scaled %+.1f%%)",
                        aligned.surface_points, aligned.surface_turn_deg, 100 * aligned.surface_scale_change);
        char text[400];
        std::snprintf(text, sizeof(text), "scale %.4g, %zu landmarks, median residual %.1f mm, rms %.1f mm%s%s%s",
                      aligned.head_from_world.scale, aligned.landmarks_used.size(), aligned.median_mm,
                      aligned.rms_mm, views, refined, aligned.message.empty() ? "" : (", " + aligned.message).c_str());
        result->message = text;
        HF_LOG(Info) << "align: " << result->message;
        return Status::Ok();
      },
      &skipped);
}

Status RunTrackStage(Workspace* workspace, const TrackStageOptions& track, const std::string& face_model,
                     const OptionSet& options, Progress* progress) {
  HF_RETURN_IF_ERROR(track.Check());
  std::string fingerprint;
  HF_RETURN_IF_ERROR(ChainedFingerprint(*workspace, "track", {"ingest", "calibrate", "align"},
                                        options.ToIni("track", true), face_model, &fingerprint));
  bool skipped = false;
  return RunStage(
      workspace, "track", fingerprint, options.ToIni("track"),
      [&](const fs::path& staging, StageResult* result) {
        IngestedCapture capture;
        HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace->root(), &capture));
        CameraSet cameras;
        HF_RETURN_IF_ERROR(CameraSet::Read(workspace->Path("cameras_head.json"), &cameras));
        FaceModel model;
        HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
        TrackSummary summary;
        HF_RETURN_IF_ERROR(RunTrack(track, capture, cameras, model, staging, progress, &summary));
        result->outputs = summary.outputs;
        char text[200];
        std::snprintf(text, sizeof(text),
                      "%d frames, median landmark residual %.2f px, %d interpolated, %d low-confidence, %.1f s%s",
                      summary.frames, summary.median_residual_px, summary.interpolated, summary.low_confidence,
                      summary.seconds, summary.fixed_head ? ", head held by the cameras" : "");
        result->message = text;
        if (summary.dropped_views > 0) {
          result->message += ", " + std::to_string(summary.dropped_views) +
                             " views left out (their landmarks disagreed with the other views of their frame)";
        }
        HF_LOG(Info) << "track: " << result->message;
        return Status::Ok();
      },
      &skipped);
}

}  // namespace headforge
