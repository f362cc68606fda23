// The on-disk workspace that makes runs resumable (DESIGN.md, "Stages and their
// contracts"). `workspace.json` records for each stage its status, the
// fingerprint of its inputs and options, its outputs and its wall time.
//
// A stage writes its outputs into a private staging folder; only when it has
// finished are they moved into the workspace and the stage marked done. So a
// stage that fails or is killed leaves the outputs of earlier runs (and of
// earlier stages) as they were, and is simply redone on the next run. A
// resumable stage (training) also keeps checkpoints in its staging folder: a
// later run with the same fingerprint is handed that folder back and goes on
// from the last checkpoint instead of starting again.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// kInterrupted: stopped on a signal after saving a checkpoint (a stage killed
// outright stays kRunning with nobody holding the lock).
enum class StageStatus { kPending, kRunning, kDone, kFailed, kInterrupted };
const char* StageStatusName(StageStatus status);

struct StageRecord {
  std::string name;
  StageStatus status = StageStatus::kPending;
  std::string fingerprint;           // hash of inputs + options of the last start
  std::vector<std::string> outputs;  // paths relative to the workspace root
  double wall_time_s = 0.0;          // of the last completed (or failed) attempt
  std::string started_at;            // ISO 8601 UTC
  std::string finished_at;
  std::string message;               // one-line summary, or the failure reason
  // Which commit of the workspace made the outputs (numbered from 1 over all
  // stages; 0: none yet, or a workspace from before the numbering), the
  // fingerprint they were made with, and the upstream stages' numbers when
  // this stage last started: an upstream stage committed again since means
  // these outputs were made from older ones. A stage redone with the
  // fingerprint its outputs already had, from the same upstream outputs (they
  // were missing, or an attempt in between failed), keeps its number, unless
  // forced or its outputs are not repeatable (StageResult::repeatable).
  long commit = 0;
  std::string committed_fingerprint;
  std::vector<std::pair<std::string, long>> made_from;
  // made_from as it was when the outputs were committed: a later attempt
  // that failed or was interrupted records what it started from in
  // made_from, and leaves the outputs (empty: from before this record).
  std::vector<std::pair<std::string, long>> committed_from;
};

class Workspace {
 public:
  enum class Mode { kReadOnly, kReadWrite };

  // Opens the workspace at `root`. kReadWrite creates it if missing and takes an
  // exclusive lock (a second concurrent run fails with a clear message).
  static Status Open(const fs::path& root, Mode mode, std::unique_ptr<Workspace>* workspace);
  // Whether `root` holds a workspace (its workspace.json).
  static bool Exists(const fs::path& root);
  // Where `stage` writes while it runs (BeginStage's staging folder).
  static fs::path StagingPath(const fs::path& root, const std::string& stage);
  ~Workspace();

  const fs::path& root() const { return root_; }
  fs::path Path(const std::string& relative) const { return root_ / relative; }

  // Records of the stages named in `order` (pending ones for those never
  // started), then of any other stage recorded.
  std::vector<StageRecord> Stages(const std::vector<std::string>& order) const;
  // nullptr when the stage has never started.
  const StageRecord* Find(const std::string& stage) const;
  // Done with this fingerprint, every recorded output still present, and not
  // out of date.
  bool IsUpToDate(const std::string& stage, const std::string& fingerprint) const;
  // Why the stage's outputs are older than what they were made from ("ingest
  // was run again after it"), or "" when they are not (or the stage is not
  // done, or its record predates the check). Only the stages the record names
  // as read are compared; the stage table lists every stage a stage reads,
  // directly or not.
  std::string OutOfDate(const std::string& stage) const;
  // The same for the outputs the stage committed last, whatever it is doing
  // now: after a failed attempt its earlier outputs are still in place (a
  // trained model render draws), and may be older than what they read.
  std::string OutputsOutOfDate(const std::string& stage) const;
  // True when the record says running but no process holds the lock: the run
  // that started it was interrupted.
  bool WasInterrupted(const std::string& stage) const;

  // Marks the stage running and returns its staging folder: empty, or, for a
  // `resumable` stage whose last attempt was interrupted (killed, or stopped
  // on a signal) with the same fingerprint, that attempt's folder with its
  // checkpoints (`*resumed` true). An earlier failure's kept files
  // (failed/<stage>/) are removed. The `upstream` stages' commits are
  // recorded as what the outputs are made from.
  Status BeginStage(const std::string& stage, const std::string& fingerprint, const std::vector<std::string>& upstream,
                    bool resumable, fs::path* staging, bool* resumed);
  // Moves each output (relative to the staging folder) into the workspace root,
  // replacing what was there, then marks the stage done, with the next commit
  // number when `forced` or its fingerprint is not the one its outputs had.
  Status CommitStage(const std::string& stage, const std::vector<std::string>& outputs,
                     double wall_time_s, const std::string& message, bool forced = false);
  // For a stage that is up to date but whose record predates `made_from` or
  // `committed_from`: records its upstream stages' present numbers (its
  // fingerprint matched, so they are what it was made from).
  Status RecordMadeFrom(const std::string& stage, const std::vector<std::string>& upstream);
  // Marks the stage failed; its previous outputs stay where they are. What the
  // failed attempt wrote (logs, a COLMAP database, ...) moves to
  // failed/<stage>/, replacing an older failure's, and `message` is rewritten
  // to point there (paths into the staging folder, or a note at the end).
  Status FailStage(const std::string& stage, std::string* message, double wall_time_s);
  // Marks the stage interrupted on request; its staging folder stays for the
  // next run to resume.
  Status InterruptStage(const std::string& stage, const std::string& message, double wall_time_s);

 private:
  Workspace() = default;
  Status Load();
  Status Save() const;
  StageRecord* Mutable(const std::string& stage);
  // Each of `upstream` with its present commit number (0: never committed).
  std::vector<std::pair<std::string, long>> UpstreamCommits(const std::vector<std::string>& upstream) const;

  fs::path root_;
  Mode mode_ = Mode::kReadOnly;
  int lock_fd_ = -1;
  std::vector<StageRecord> records_;
  long commits_ = 0;  // the last commit number given
};

// One attempt at a stage, as RunStage makes it.
struct StageRun {
  std::string name;
  std::string fingerprint;  // hash of the stage's inputs and options
  std::string options_ini;  // the effective options, written beside the outputs as <name>.ini
  bool resumable = false;   // keeps checkpoints in its staging folder (Workspace::BeginStage)
  bool force = false;       // run even when up to date, from a clean staging folder
  std::vector<std::string> upstream = {};  // the stages whose outputs it reads (Workspace::OutOfDate)
};

// What the body of a stage is handed.
struct StageContext {
  fs::path staging;      // where it writes its outputs (and checkpoints)
  bool resumed = false;  // staging holds an interrupted attempt's checkpoints
};

// What a stage body reports back to RunStage.
struct StageResult {
  std::vector<std::string> outputs;  // relative to the staging folder
  std::string message;               // one-line summary for `status`
  // False when the same inputs and options can give other outputs (COLMAP's
  // model differs run to run): committed with a new number even under its
  // old fingerprint, so what read the earlier outputs is out of date.
  bool repeatable = true;
};

using StageBody = std::function<Status(const StageContext& context, StageResult* result)>;

// Runs `body` as `run.name` unless it is up to date: done with
// `run.fingerprint`, its outputs present and none of its upstream stages run
// again since (Workspace::OutOfDate).
// The body writes into the staging folder; RunStage writes the options there
// as <name>.ini, commits, and records the wall time. `*skipped` tells whether
// the body ran. When the body fails, what it wrote is kept in failed/<stage>/
// and the error names that folder (paths into the staging folder in the
// message are rewritten to point there). A body that returns
// Status::Interrupted leaves its staging folder for the next run to resume.
Status RunStage(Workspace* workspace, const StageRun& run, const StageBody& body, bool* skipped);

// Current UTC time as ISO 8601 text.
std::string NowIso8601();

}  // namespace headforge
