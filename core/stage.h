// A pipeline stage as the stage table sees it (DESIGN.md, "Stages and their
// contracts"): its options, what it reads and writes, and its run function
// behind one interface, so that the per-stage commands, `run`, `status` and
// the fingerprints all come from one table (pipelines/stage_table.h) and
// adding a stage is one entry plus its own files.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/hash.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/workspace.h"

namespace headforge {

// What every stage resolves the same way, once, from the common options.
struct StageSettings {
  std::string data_dir;    // the shared data folder
  std::string face_model;  // the face model file (Basel-layout HDF5)
  int threads = 1;         // worker threads, resolved (>= 1)
  std::string workspace;   // the workspace's folder ("" outside a workspace command)
};

// What a stage's run function is handed besides its staging folder.
struct StageEnv {
  const Workspace* workspace;  // upstream stages' outputs are read from its root
  const StageSettings* settings;
  Progress* progress;
};

// One stage's options and work.
class StageJob {
 public:
  virtual ~StageJob() = default;
  // Binds the stage's options (keys "<stage>.*").
  virtual void AddOptions(OptionSet* options) = 0;
  // After parsing: fills defaults that live under the data folder, or that
  // a preset gives to the options `parsed` says nobody set.
  virtual void Resolve(const StageSettings& settings, const OptionSet& parsed) {}
  // Says which option is wrong and why.
  virtual Status Check() const = 0;
  // Inputs other than upstream stages' outputs that decide the outputs
  // (ingest: the videos' contents); options and upstream fingerprints are
  // hashed by the runner.
  virtual Status AddInputs(Hasher* hasher) const { return Status::Ok(); }
  // In `headforge run`, after each earlier stage: whether what is in the
  // workspace already rules this stage out (train: too few frames), so that
  // the run stops before the stages between spend their time for nothing.
  virtual Status Ahead(const fs::path& workspace) const { return Status::Ok(); }
  // Writes the stage's outputs into `context.staging` and names them in
  // `result` with a one-line summary.
  virtual Status Run(const StageEnv& env, const StageContext& context, StageResult* result) = 0;

  // One stage run by several processes (train under torchrun or srun): the
  // stage's own command, and `headforge run` when it reaches the stage,
  // call Join before they open the workspace. A process
  // that follows another (`*follows`) calls Follow in place of the stage:
  // it works beside the leading one without the workspace's lock and writes
  // nothing. The leading process runs the stage, then Finish (whether the
  // stage ran, was up to date or failed).
  virtual Status Join(bool* follows) {
    *follows = false;
    return Status::Ok();
  }
  virtual Status Follow(const StageSettings& settings, const fs::path& workspace) { return Status::Ok(); }
  virtual void Finish() {}
};

struct StageEntry {
  std::string name;
  std::vector<std::string> upstream;  // stages whose outputs it reads; each must be done first
  std::string summary;                // one line for `headforge --help`
  std::string usage;                  // first line of `headforge <stage> --help`
  std::string description;            // the rest of it
  std::vector<std::string> reads;     // workspace files it reads (documentation, --help)
  std::vector<std::string> writes;    // what it may write
  // Bumped when the stage's outputs change for the same inputs and options.
  int version = 1;
  bool uses_face_model = false;  // the face model file's stamp enters the fingerprint
  bool resumable = false;        // keeps checkpoints across interruptions (Workspace::BeginStage)
  // Empty: the stage is available; else why not (said when it is asked for).
  std::string unavailable;
  std::function<std::unique_ptr<StageJob>()> make;
};

// Fails, naming what to run, when one of `stages` is not done or its outputs
// are out of date (Workspace::OutOfDate: a stage it reads was run again since).
// `who` begins the message ("train", "render").
Status RequireStagesCurrent(const Workspace& workspace, const std::vector<std::string>& stages, const std::string& who);

// The fingerprint of `entry` run by `job` with `options` (the options' INI
// text of its section, its version, every upstream stage's fingerprint, the
// face model's stamp, the job's own inputs). Fails, naming the stage to run,
// when an upstream stage is not done or out of date.
Status StageFingerprint(const StageEntry& entry, const StageJob& job, const OptionSet& options,
                        const Workspace& workspace, const StageSettings& settings, std::string* fingerprint);

// Runs the stage into the workspace, or skips it when it is up to date
// (`force`: runs it even then). `*skipped` says which.
Status RunStageJob(const StageEntry& entry, StageJob* job, const OptionSet& options, Workspace* workspace,
                   const StageSettings& settings, Progress* progress, bool force, bool* skipped);

}  // namespace headforge
