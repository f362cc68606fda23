// The train stage's job: the avatar model trained on the tracked workspace,
// into models/<model>/. Its --model defaults to auto: the model is chosen
// from the aligned cameras when the stage runs (ChooseModel), and said.
#include <nlohmann/json.hpp>

#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "core/fs.h"
#include "core/json_io.h"
#include "core/log.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

// train --extend: the trained model in `trained` (a run its time limit
// stopped, its checkpoint kept) copied into `staging`, where training goes on
// from the checkpoint under `options`, which may differ from the recorded
// run's only in the time limit.
Status PrepareExtension(const fs::path& trained, const TrainOptions& options, const fs::path& staging) {
  std::error_code ec;
  if (!fs::exists(trained / "checkpoint.pt", ec))
    return Status::InvalidArgument(
        "train --extend: " + trained.string() + " holds no checkpoint to go on from: only a gaussian-style training "
        "that its time limit stopped keeps one (without stage 3); train without --extend starts afresh");
  nlohmann::json config;
  HF_RETURN_IF_ERROR(ReadJson(trained / "config.json", &config));
  if (!config.contains("options"))
    return Status::InvalidArgument("train --extend: " + (trained / "config.json").string() +
                                      " does not record its options (an older model); train without --extend");
  TrainOptions recorded = TrainOptionsFromJson(config.at("options"));
  if (recorded.loop.max_minutes <= 0 || (options.loop.max_minutes > 0 && options.loop.max_minutes <= recorded.loop.max_minutes))
    return Status::InvalidArgument("train --extend: give a --max-minutes above the " +
                                   std::to_string(recorded.loop.max_minutes).substr(0, 5) +
                                   " the training stopped at (0: no limit)");
  recorded.loop.max_minutes = options.loop.max_minutes;
  TrainOptions asked = options;
  asked.data = options.DataFor(kGaussianStyle);
  const nlohmann::json was = ToJson(recorded), now = ToJson(asked);
  if (was != now) {
    std::string differ;
    for (const auto& [key, value] : now.items())
      if (!was.contains(key) || was.at(key) != value) differ += (differ.empty() ? "" : ", ") + key;
    return Status::InvalidArgument("train --extend goes on with the same training: only --max-minutes may change (" +
                                   (differ.empty() ? std::string("the options") : differ) +
                                   " differ from the recorded run's); train without --extend starts afresh");
  }
  HF_RETURN_IF_ERROR(EnsureDirectory(staging.parent_path()));
  fs::copy(trained, staging, fs::copy_options::recursive, ec);
  if (ec) return Status::IoError("train --extend: cannot copy " + trained.string() + ": " + ec.message());
  HF_LOG(Info) << "train: --extend: going on from the checkpoint of the training the time limit stopped";
  return Status::Ok();
}

class TrainJob : public StageJob {
 public:
  TrainJob() { options_.model = "auto"; }
  void AddOptions(OptionSet* options) override {
    AddTrainOptions(options, &options_);
    options->Add("train.extend", &extend_,
                 "Go on with a gaussian-style training its time limit stopped, from the checkpoint kept with its "
                 "model, under a longer --max-minutes (0: none); every other option as it trained.",
                 "extend", OptionSet::Effect::kRuntime);
  }
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
    if (extend_ && !context.resumed) {
      if (!kGaussianStyle.Is(model))
        return Status::InvalidArgument("train --extend goes on with a gaussian-style training, not " + model);
      HF_RETURN_IF_ERROR(PrepareExtension(env.workspace->root() / "models" / folder, *options,
                                          context.staging / "models" / folder));
    }
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
  bool extend_ = false;
  std::vector<TrainOptions> resolved_;  // per model that may run
  Status preset_;
};

}  // namespace

std::unique_ptr<StageJob> MakeTrainJob() { return std::make_unique<TrainJob>(); }

}  // namespace headforge
