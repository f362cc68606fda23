#include "core/stage.h"

#include "core/interrupt.h"
#include "core/log.h"

namespace headforge {

Status RequireStagesCurrent(const Workspace& workspace, const std::vector<std::string>& stages, const std::string& who) {
  for (const auto& name : stages) {
    const StageRecord* r = workspace.Find(name);
    if (!r || r->status != StageStatus::kDone)
      return Status::InvalidArgument(who + " needs the " + name + " stage first (headforge " + name +
                                     " or headforge run)");
    if (const std::string why = workspace.OutOfDate(name); !why.empty())
      return Status::InvalidArgument(who + " needs " + name + " run again first: its outputs are out of date (" + why +
                                     "); run headforge " + name + " and the stages after it again, or headforge run --workspace " +
                                     workspace.root().string() + " with the options you gave them");
  }
  return Status::Ok();
}

Status StageFingerprint(const StageEntry& entry, const StageJob& job, const OptionSet& options,
                        const Workspace& workspace, const StageSettings& settings, std::string* fingerprint) {
  Hasher h;
  h.Add(entry.name + "-" + std::to_string(entry.version)).Add(options.ToIni(entry.name, true));
  HF_RETURN_IF_ERROR(RequireStagesCurrent(workspace, entry.upstream, entry.name));
  for (const auto& name : entry.upstream) h.Add(workspace.Find(name)->fingerprint);
  if (entry.uses_face_model) {
    std::error_code ec;
    if (!fs::is_regular_file(settings.face_model, ec))
      return Status::NotFound(entry.name + ": no face model at " + settings.face_model +
                              " (give --face-model FILE, or --data DIR with ict_facekit/ict_face_model.h5 in it; "
                              "headforge face-model import-ict builds one from ICT-FaceKit's folder)");
    HF_RETURN_IF_ERROR(h.AddFileDigest(settings.face_model).WithContext("face model"));
  }
  HF_RETURN_IF_ERROR(job.AddInputs(&h).WithContext(entry.name));
  *fingerprint = h.Hex();
  return Status::Ok();
}

Status RunStageJob(const StageEntry& entry, StageJob* job, const OptionSet& options, Workspace* workspace,
                   const StageSettings& settings, Progress* progress, bool force, bool* skipped) {
  if (!entry.unavailable.empty()) return Status::InvalidArgument(entry.name + ": " + entry.unavailable);
  HF_RETURN_IF_ERROR(job->Check());
  StageRun run;
  run.name = entry.name;
  run.options_ini = options.ToIni(entry.name);
  run.resumable = entry.resumable;
  run.upstream = entry.upstream;
  HF_RETURN_IF_ERROR(StageFingerprint(entry, *job, options, *workspace, settings, &run.fingerprint));
  run.force = force;
  // A resumable stage stops on SIGINT/SIGTERM after writing a checkpoint.
  std::unique_ptr<InterruptScope> interrupts;
  if (entry.resumable) interrupts = std::make_unique<InterruptScope>();
  const StageEnv env{workspace, &settings, progress};
  return RunStage(
      workspace, run,
      [&](const StageContext& context, StageResult* result) {
        HF_RETURN_IF_ERROR(job->Run(env, context, result));
        HF_LOG(Info) << entry.name << ": " << result->message;
        return Status::Ok();
      },
      skipped);
}

}  // namespace headforge
