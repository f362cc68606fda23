// The calibrate stage's job: cameras for the ingested frames (COLMAP, head
// pose refined with the face model, or a rig file).
#include "calibration/calibrate.h"
#include "calibration/landmark_embedding.h"
#include "pipelines/stage_jobs.h"
#include "reconstruction/track_stage.h"

namespace headforge {
namespace {

class CalibrateJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddCalibrateOptions(options, &options_); }
  Status Check() const override { return options_.Check(); }
  Status AddInputs(Hasher* hasher) const override {
    return AddLandmarkEmbeddingInputs({options_.landmark_embedding}, hasher);
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    IngestedCapture capture;
    HF_RETURN_IF_ERROR(ReadIngestedCapture(env.workspace->root(), &capture));
    FaceModel model;
    HF_RETURN_IF_ERROR(FaceModel::Load(env.settings->face_model, &model));
    CalibrateOptions effective = options_;
    effective.colmap.threads = env.settings->threads;
    CameraSet cameras;
    CalibrateSummary summary;
    HF_RETURN_IF_ERROR(RunCalibrate(effective, capture, model, context.staging, env.progress, &cameras, &summary));
    bool refined = false;
    HF_RETURN_IF_ERROR(RefineHeadPoseStep(effective, capture, model, env.settings->threads, env.progress, &cameras,
                                          &summary, &refined));
    if (refined) HF_RETURN_IF_ERROR(cameras.Write(context.staging / "cameras.json"));
    result->outputs = {"cameras.json"};
    if (fs::exists(context.staging / "colmap")) result->outputs.push_back("colmap");
    result->message = summary.OneLine();
    result->repeatable = summary.mode != "colmap";  // its threads place the cameras a little differently each run
    return Status::Ok();
  }

 private:
  CalibrateOptions options_;
};

}  // namespace

std::unique_ptr<StageJob> MakeCalibrateJob() { return std::make_unique<CalibrateJob>(); }

}  // namespace headforge
