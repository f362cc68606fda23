// Each stage run inside a workspace: fingerprint, skip when up to date, run into
// staging, commit. Shared by the stage's own command and by `run`.
#pragma once

#include "capture/ingest.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/workspace.h"

namespace headforge {

// Runs (or skips) ingest; `options` is the parsed OptionSet whose "ingest"
// section is recorded as ingest.ini and enters the fingerprint.
Status RunIngestStage(Workspace* workspace, const IngestOptions& ingest, const OptionSet& options,
                      int threads, Progress* progress);

}  // namespace headforge
