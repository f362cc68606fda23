// The track stage's job: the face model fitted to the landmarks over the sequence.
#include <cstdio>

#include "calibration/landmark_embedding.h"
#include "pipelines/stage_jobs.h"
#include "reconstruction/track_stage.h"

namespace headforge {
namespace {

class TrackJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddTrackOptions(options, &options_); }
  void Resolve(const StageSettings& settings, const OptionSet&) override { options_.fit.threads = settings.threads; }
  Status Check() const override { return options_.Check(); }
  Status AddInputs(Hasher* hasher) const override {
    // Empty: one of the shipped files, chosen from the cameras when it runs.
    HF_RETURN_IF_ERROR(AddLandmarkEmbeddingInputs(options_.landmark_embedding.empty()
                                                      ? std::vector<std::string>{ViewLandmarkEmbedding(),
                                                                                 IdentityLandmarkEmbedding()}
                                                      : std::vector<std::string>{options_.landmark_embedding},
                                                  hasher));
    // The mesh's embedding counts wherever a fit may read it (a rig's
    // surrounding views take multiview_mesh_weight).
    const bool read = options_.fit.mesh_weight > 0 || options_.multiview_mesh_weight > 0;
    return AddMeshEmbeddingInputs(read ? options_.mesh_embedding : "", hasher);
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    IngestedCapture capture;
    HF_RETURN_IF_ERROR(ReadIngestedCapture(env.workspace->root(), &capture));
    CameraSet cameras;
    HF_RETURN_IF_ERROR(CameraSet::Read(env.workspace->Path("cameras_head.json"), &cameras));
    FaceModel model;
    HF_RETURN_IF_ERROR(FaceModel::Load(env.settings->face_model, &model));
    TrackSummary summary;
    HF_RETURN_IF_ERROR(RunTrack(options_, capture, cameras, model, context.staging, env.progress, &summary));
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
    return Status::Ok();
  }

 private:
  TrackStageOptions options_;
};

}  // namespace

std::unique_ptr<StageJob> MakeTrackJob() { return std::make_unique<TrackJob>(); }

}  // namespace headforge
