// `headforge ingest` and `headforge run`.
#include <cstdio>

#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "pipelines/commands.h"
#include "pipelines/stages.h"

namespace headforge {
namespace {

// Opens the workspace and runs ingest with the parsed options.
int IngestInWorkspace(const CommonOptions& common, IngestOptions* ingest, const OptionSet& options) {
  ResolveIngestDefaults(common.data_dir, ingest);
  if (Status s = ingest->Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (Status s = Workspace::Open(common.workspace, Workspace::Mode::kReadWrite, &workspace); !s.ok())
    return ReportFailure(s);
  StderrProgress progress;
  const int threads = common.threads > 0 ? common.threads : 0;
  const Status status =
      RunIngestStage(workspace.get(), *ingest, options, threads > 0 ? threads : HardwareThreads(),
                     &progress);
  if (!status.ok()) return ReportFailure(status);
  return kExitOk;
}

}  // namespace

int IngestCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  IngestOptions ingest;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  AddIngestOptions(&options, &ingest);
  const std::string usage = "headforge ingest --video FILE|DIR... --workspace DIR [options]";
  const int parsed = ParseOrExit(
      &options, args, usage,
      "Samples frames from one video or image folder per camera, drops blurred frames, detects\n"
      "the face and its 68 landmarks, crops and resizes around the head, and makes a head mask.\n"
      "Writes frames/, masks/, landmarks.json and capture.json into the workspace.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  return IngestInWorkspace(common, &ingest, options);
}

int RunCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  IngestOptions ingest;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  AddIngestOptions(&options, &ingest);
  const std::string usage = "headforge run --video FILE|DIR... --workspace DIR [options]";
  const int parsed = ParseOrExit(
      &options, args, usage,
      "Runs the pipeline's stages in order into one workspace: ingest (available now), then\n"
      "calibrate, align, track, train and export as they become available. A stage whose\n"
      "inputs and options are unchanged is skipped; a failed or interrupted one is redone.\n"
      "Options of every stage are accepted, by their short flag or their dotted key.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  const int code = IngestInWorkspace(common, &ingest, options);
  if (code != kExitOk) return code;
  HF_LOG(Info) << "run: ingest is the last stage available in this version; results are in "
               << common.workspace << " (headforge status " << common.workspace << ")";
  return kExitOk;
}

}  // namespace headforge
