// The train stage's job: the avatar model trained on the tracked workspace,
// into models/<model>/. Its --model defaults to auto: the model is chosen
// from the aligned cameras when the stage runs (ChooseModel), and said.
#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "core/log.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

class TrainJob : public StageJob {
 public:
  TrainJob() { options_.model = "auto"; }
  void AddOptions(OptionSet* options) override { AddTrainOptions(options, &options_); }
  void Resolve(const StageSettings&, const OptionSet& parsed) override {
    // Each model's preset differs: resolve both now, while `parsed` says
    // which options were given, and pick one when the cameras are known.
    for (const AvatarModel& model : kAvatarModels) {
      if (options_.model != "auto" && !model.Is(options_.model)) continue;
      TrainOptions resolved = options_;
      resolved.model = model.Name();
      if (Status s = ApplyTrainPreset(parsed, &resolved); !s.ok() && preset_.ok()) preset_ = s;
      resolved_.push_back(resolved);
    }
  }
  Status Check() const override {
    HF_RETURN_IF_ERROR(preset_);
    if (resolved_.empty()) return options_.Check();  // an unknown model: says which ones there are
    // With auto, options only one model takes (a render size for the
    // gan-avatar's volume) are fine until the model is chosen; Run checks
    // the chosen one's again.
    // An option neither model takes (a bad step count) is said as it is.
    Status first;
    bool same = true;
    for (const TrainOptions& t : resolved_) {
      const Status s = t.Check();
      if (s.ok()) return s;
      if (first.ok()) first = s;
      same = same && s.message() == first.message();
    }
    return options_.model == "auto" && !same ? first.WithContext("--model auto: no model takes these options") : first;
  }
  Status Ahead(const fs::path& workspace) const override {
    return CheckEnoughFramesToTrain(workspace, options_.data.holdout);
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    std::string model = options_.model, why = "as asked";
    if (model == "auto") HF_RETURN_IF_ERROR(ChooseModel(env.workspace->root(), &model, &why));
    const TrainOptions* options = nullptr;
    for (const TrainOptions& t : resolved_)
      if (t.model == model) options = &t;
    if (!options) return Status::Internal("train: no options resolved for " + model);
    if (Status s = options->Check(); !s.ok())
      return s.WithContext("--model auto chose " + model + " (" + why + "); give --model to choose");
    HF_LOG(Info) << "train: " << model << " (" << (options_.model == "auto" ? "--model auto: " : "") << why
                 << (options_.model == "auto" ? "; --model " + AvatarModelNames() + " chooses" : "") << ")";
    const std::string folder(FindAvatarModel(model)->folder);
    TrainSummary summary;
    HF_RETURN_IF_ERROR(RunTrain(*options, env.workspace->root(), env.settings->face_model,
                                context.staging / "models" / folder, env.progress, &summary));
    result->outputs = {"models/" + folder};
    const std::string& generator_from = options->gan_avatar.generator_from;
    const std::string how = generator_from.empty() ? options->preset : "the GAN of " + generator_from;
    result->message = model + " (" + how + (options_.model == "auto" ? ", auto: " + why : "") +
                      "): " + summary.OneLine();
    return Status::Ok();
  }

 private:
  TrainOptions options_;
  std::vector<TrainOptions> resolved_;  // per model that may run
  Status preset_;
};

}  // namespace

std::unique_ptr<StageJob> MakeTrainJob() { return std::make_unique<TrainJob>(); }

}  // namespace headforge
