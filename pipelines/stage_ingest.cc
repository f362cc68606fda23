// The ingest stage's job: videos or image folders -> frames, masks, landmarks.
#include "avatar/avatar_train.h"
#include "capture/ingest.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

class IngestJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddIngestOptions(options, &options_); }
  void Resolve(const StageSettings& settings, const OptionSet& parsed) override {
    ResolveIngestDefaults(settings.data_dir, &options_);
    // In `headforge run`, the training preset's frame budget unless --select
    // is given.
    const auto preset = parsed.Value("train.preset");
    if (!parsed.WasGiven("ingest.select") && preset && preset->size() == 1)
      options_.select = PresetFrameBudget(preset->front());
  }
  Status Check() const override { return options_.Check(); }
  Status AddInputs(Hasher* hasher) const override { return AddIngestInputs(options_, hasher); }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    IngestSummary summary;
    HF_RETURN_IF_ERROR(RunIngest(options_, context.staging, env.settings->threads, env.progress, &summary));
    result->outputs = {"frames", "masks", "landmarks.json", "capture.json"};
    result->message = summary.OneLine();
    return Status::Ok();
  }

 private:
  IngestOptions options_;
};

}  // namespace

std::unique_ptr<StageJob> MakeIngestJob() { return std::make_unique<IngestJob>(); }

}  // namespace headforge
