// The align stage's job: the similarity to the face model's head frame.
#include <cstdio>
#include <cstring>

#include "calibration/align.h"
#include "calibration/landmark_embedding.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

std::string AlignSummary(const AlignResult& aligned) {
  char refined[80] = "";
  if (aligned.reprojection_median_px > 0)
    std::snprintf(refined, sizeof(refined), ", landmark reprojection %.1f px", aligned.reprojection_median_px);
  char views[160] = "";
  if (aligned.views_used > 0) std::snprintf(views, sizeof(views), ", rotation from %d views", aligned.views_used);
  if (aligned.surface_points > 0)
    std::snprintf(views + std::strlen(views), sizeof(views) - std::strlen(views),
                  ", surface fit on %d points on the face (turned %.2f deg, scaled %+.1f%%)", aligned.surface_points,
                  aligned.surface_turn_deg, 100 * aligned.surface_scale_change);
  char text[400];
  std::snprintf(text, sizeof(text), "scale %.4g, %zu landmarks, median residual %.1f mm, rms %.1f mm%s%s%s",
                aligned.head_from_world.scale, aligned.landmarks_used.size(), aligned.median_mm, aligned.rms_mm, views,
                refined, aligned.message.empty() ? "" : (", " + aligned.message).c_str());
  return text;
}

class AlignJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddAlignOptions(options, &options_); }
  Status Check() const override { return options_.Check(); }
  Status AddInputs(Hasher* hasher) const override {
    HF_RETURN_IF_ERROR(AddLandmarkEmbeddingInputs({options_.landmark_embedding}, hasher));
    // The face mesh's embedding, where a rig's view poses read it.
    if (options_.rig_view_poses == "mesh" && fs::exists(options_.mesh_embedding)) {
      hasher->Add(std::string("mesh embedding"));
      HF_RETURN_IF_ERROR(hasher->AddFileDigest(options_.mesh_embedding).WithContext("mesh embedding"));
    }
    return Status::Ok();
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    IngestedCapture capture;
    HF_RETURN_IF_ERROR(ReadIngestedCapture(env.workspace->root(), &capture));
    CameraSet cameras;
    HF_RETURN_IF_ERROR(CameraSet::Read(env.workspace->Path("cameras.json"), &cameras));
    FaceModel model;
    HF_RETURN_IF_ERROR(FaceModel::Load(env.settings->face_model, &model));
    AlignResult aligned;
    HF_RETURN_IF_ERROR(RunAlign(options_, capture, cameras, model, &aligned));
    HF_RETURN_IF_ERROR(WriteAlignment(aligned, context.staging / "alignment.json"));
    HF_RETURN_IF_ERROR(aligned.cameras.Write(context.staging / "cameras_head.json"));
    result->outputs = {"alignment.json", "cameras_head.json"};
    result->message = AlignSummary(aligned);
    return Status::Ok();
  }

 private:
  AlignOptions options_;
};

}  // namespace

std::unique_ptr<StageJob> MakeAlignJob() { return std::make_unique<AlignJob>(); }

}  // namespace headforge
