// The train stage's job: the avatar model trained on the tracked workspace,
// into models/<model>/.
#include "avatar/avatar_train.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

class TrainJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddTrainOptions(options, &options_); }
  void Resolve(const StageSettings&, const OptionSet& parsed) override { preset_ = ApplyTrainPreset(parsed, &options_); }
  Status Check() const override {
    HF_RETURN_IF_ERROR(preset_);
    return options_.Check();
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    const std::string folder = options_.model == "gan-avatar" ? "gan_avatar" : "gaussian_style";
    TrainSummary summary;
    HF_RETURN_IF_ERROR(RunTrain(options_, env.workspace->root(), env.settings->face_model,
                                context.staging / "models" / folder, env.progress, &summary));
    result->outputs = {"models/" + folder};
    result->message = options_.model + " (" + options_.preset + "): " + summary.OneLine();
    return Status::Ok();
  }

 private:
  TrainOptions options_;
  Status preset_;
};

}  // namespace

std::unique_ptr<StageJob> MakeTrainJob() { return std::make_unique<TrainJob>(); }

}  // namespace headforge
