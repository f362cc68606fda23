// The export stage's job: the trained avatar in the formats other tools open, into export/.
#include "export/export.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

class ExportJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddExportOptions(options, &options_); }
  void Resolve(const StageSettings&, const OptionSet&) override {}
  Status Check() const override { return options_.Check(); }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    ExportSummary summary;
    HF_RETURN_IF_ERROR(RunExport(options_, env.workspace->root(), env.settings->face_model,
                                 context.staging / "export", env.progress, &summary));
    result->outputs = {"export"};
    result->message = summary.OneLine() + " in " + (env.workspace->root() / "export").string();
    return Status::Ok();
  }

 private:
  ExportOptions options_;
};

}  // namespace

std::unique_ptr<StageJob> MakeExportJob() { return std::make_unique<ExportJob>(); }

}  // namespace headforge
