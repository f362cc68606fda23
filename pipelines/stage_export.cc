// The export stage's job: the trained avatar in the formats other tools open, into export/.
#include "avatar/model_table.h"
#include "core/hash.h"
#include "core/log.h"
#include "core/options.h"
#include "core/paths.h"
#include "export/export.h"
#include "pipelines/stage_jobs.h"

namespace headforge {
namespace {

class ExportJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override { AddExportOptions(options, &options_); }
  void Resolve(const StageSettings& settings, const OptionSet&) override {
    workspace_ = settings.workspace;
    // --formats mesh,report as well as --formats mesh report.
    options_.formats = SplitCommaList(options_.formats);
    // The identity score finds faces as ingest does.
    options_.ultraface_dir = (fs::path(settings.data_dir) / "models" / "ultraface").string();
    options_.landmark_model = DefaultLandmarkModel();
  }
  Status Check() const override { return options_.Check(); }
  // The trained model is not an upstream stage (the mesh avatar and the
  // report need only tracking), so its files enter the fingerprint here:
  // training again makes export run again. Whole: a model trained again
  // has the same size, and may differ in a few of its bytes.
  Status AddInputs(Hasher* hasher) const override {
    for (const AvatarModel& entry : kAvatarModels) {
      const std::string folder(entry.folder);
      const fs::path model = entry.Dir(workspace_);
      for (const char* file : {"config.json", "model.pt"}) {
        hasher->Add(std::string(folder) + "/" + file);
        if (fs::exists(model / file)) {
          HF_RETURN_IF_ERROR(hasher->AddFileContents(model / file));
        } else {
          hasher->Add(std::string("none"));
        }
      }
    }
    // The benches' results the report shows.
    for (const fs::path& file : BenchResultFiles(options_, workspace_)) {
      hasher->Add(fs::relative(file, workspace_).string());
      HF_RETURN_IF_ERROR(hasher->AddFileContents(file));
    }
    return AddExportAssets(options_, hasher);
  }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override {
    if (ExportNeedsModel(options_))
      if (const std::string why = env.workspace->OutputsOutOfDate("train"); !why.empty())
        HF_LOG(Warning) << "export: the trained model is older than the tracked capture (" << why
                        << "); headforge train makes it again from the present one";
    ExportSummary summary;
    HF_RETURN_IF_ERROR(RunExport(options_, env.workspace->root(), env.settings->face_model,
                                 context.staging / "export", env.progress, &summary));
    result->outputs = {"export"};
    result->message = summary.OneLine() + " in " + (env.workspace->root() / "export").string();
    return Status::Ok();
  }

 private:
  ExportOptions options_;
  std::string workspace_;
};

}  // namespace

std::unique_ptr<StageJob> MakeExportJob() { return std::make_unique<ExportJob>(); }

}  // namespace headforge
