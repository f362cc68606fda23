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
    options->Add("train.distributed", &distributed_,
                 "auto: when torchrun (RANK, WORLD_SIZE, MASTER_ADDR, MASTER_PORT) or srun (several tasks) starts "
                 "this command once per rank, the gaussian-style model's stages 1-2 train data-parallel: rank 0 "
                 "runs the stage on the workspace, the others train beside it and write nothing (docs/cluster.md); "
                 "off: one process, whatever the environment says.",
                 "distributed", OptionSet::Effect::kRuntime);
    options->Add("train.distributed_timeout", &distributed_timeout_,
                 "Seconds the ranks wait for one another (at the start, and for each step's sums) before a rank "
                 "that does not answer fails the run.",
                 "distributed-timeout", OptionSet::Effect::kRuntime);
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
  Status Join(bool* follows) override {
    *follows = false;
    if (distributed_ != "auto" && distributed_ != "off")
      return Status::InvalidArgument("--distributed takes auto or off, not '" + distributed_ + "'");
    if (!(distributed_timeout_ > 0)) return Status::InvalidArgument("--distributed-timeout takes seconds above 0");
    HF_RETURN_IF_ERROR(TrainRanks::Join(distributed_, distributed_timeout_, &ranks_));
    *follows = ranks_ != nullptr && ranks_->rank() > 0;
    return Status::Ok();
  }
  Status Follow(const StageSettings& settings, const fs::path& workspace) override {
    // Rank 0's word first: under headforge run it comes once the stages
    // before train have run, and the model's choice reads what they made.
    bool training = false;
    HF_RETURN_IF_ERROR(ranks_->Hear(&training).WithContext("rank " + std::to_string(ranks_->rank())));
    if (!training) {
      HF_LOG(Info) << "train: rank " << ranks_->rank() << ": rank 0 did not train (the stage was up to date, or "
                   << "it stopped before training: its log says why)";
      return Status::Ok();
    }
    std::string model, why;
    const TrainOptions* options = nullptr;
    HF_RETURN_IF_ERROR(Choose(workspace, &model, &why, &options));
    const fs::path out = Workspace::StagingPath(workspace, "train") / "models" / std::string(FindAvatarModel(model)->folder);
    bool trained = false;
    HF_RETURN_IF_ERROR(FollowTrain(*options, workspace, settings.face_model, out, ranks_.get(), &trained)
                           .WithContext("rank " + std::to_string(ranks_->rank())));
    if (trained)
      HF_LOG(Info) << "train: rank " << ranks_->rank() << " of " << ranks_->world()
                   << ": trained stages 1-2 beside rank 0, which wrote the model";
    return Status::Ok();
  }
  void Finish() override {
    // Ranks waiting for rank 0's word go home when it did not train.
    if (ranks_ != nullptr && !ranks_->told())
      if (Status s = ranks_->Tell(false); !s.ok()) HF_LOG(Warning) << "train: " << s.message();
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    std::string model, why;
    const TrainOptions* options = nullptr;
    HF_RETURN_IF_ERROR(Choose(env.workspace->root(), &model, &why, &options));
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
                                context.staging / "models" / folder, env.progress, &summary, ranks_.get()));
    result->outputs = {"models/" + folder};
    const std::string& generator_from = options->gan_avatar.generator_from;
    const std::string how = generator_from.empty() ? options->preset : "the GAN of " + generator_from;
    result->message = model + " (" + how + (options_.model == "auto" ? ", auto: " + why : "") +
                      "): " + summary.OneLine();
    return Status::Ok();
  }

 private:
  // The model to train (--model, or auto's choice from the workspace's
  // cameras), why, and its resolved options.
  Status Choose(const fs::path& workspace, std::string* model, std::string* why, const TrainOptions** options) const {
    *model = options_.model;
    *why = "as asked";
    if (*model == "auto") HF_RETURN_IF_ERROR(ChooseModel(workspace, model, why));
    *options = nullptr;
    for (const TrainOptions& t : resolved_)
      if (t.model == *model) *options = &t;
    if (!*options) return Status::Internal("train: no options resolved for " + *model);
    if (Status s = (*options)->Check(); !s.ok())
      return s.WithContext("--model auto chose " + *model + " (" + *why + "); give --model to choose");
    return Status::Ok();
  }

  TrainOptions options_;
  bool extend_ = false;
  std::string distributed_ = "auto";
  double distributed_timeout_ = 1800;
  std::unique_ptr<TrainRanks> ranks_;  // a data-parallel run's, joined
  std::vector<TrainOptions> resolved_;  // per model that may run
  Status preset_;
};

}  // namespace

std::unique_ptr<StageJob> MakeTrainJob() { return std::make_unique<TrainJob>(); }

}  // namespace headforge
