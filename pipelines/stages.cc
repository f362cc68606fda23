#include "pipelines/stages.h"

#include "core/log.h"

namespace headforge {

Status RunIngestStage(Workspace* workspace, const IngestOptions& ingest, const OptionSet& options,
                      int threads, Progress* progress) {
  HF_RETURN_IF_ERROR(ingest.Check());
  std::string fingerprint;
  HF_RETURN_IF_ERROR(IngestFingerprint(ingest, options.ToIni("ingest", true), &fingerprint)
                         .WithContext("ingest"));
  bool skipped = false;
  return RunStage(
      workspace, "ingest", fingerprint, options.ToIni("ingest"),
      [&](const fs::path& staging, StageResult* result) {
        IngestSummary summary;
        HF_RETURN_IF_ERROR(RunIngest(ingest, staging, threads, progress, &summary));
        result->outputs = {"frames", "masks", "landmarks.json", "capture.json"};
        result->message = summary.OneLine();
        HF_LOG(Info) << "ingest: " << result->message;
        return Status::Ok();
      },
      &skipped);
}

}  // namespace headforge
