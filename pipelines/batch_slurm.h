// Many captures on a Slurm cluster: each stage of each capture's workspace is
// one element of a job array, one array per stage, element i depending on
// element i of the previous stage's array (--dependency=aftercorr), so one
// capture's failure cancels only its own later stages
// (--kill-on-invalid-dep=yes). Every job runs `headforge batch job`, which
// reads its capture's row from the batch's batch.json (never from a shell
// line) and runs `headforge run --until <stage>` on it: stages already done
// and up to date are skipped, so a batch submitted again redoes only what is
// not done. A job given SIGTERM (--signal=B:TERM@seconds before its limit)
// stops its stage, which checkpoints when it keeps checkpoints (train),
// requeues itself and exits kBatchExitInterrupted; the requeued job resumes.
#pragma once

#include <iosfwd>
#include <map>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"
#include "pipelines/batch_manifest.h"

namespace headforge {

// `headforge batch job`'s exit code when a signal stopped its stage (EX_TEMPFAIL).
constexpr int kBatchExitInterrupted = 75;

// What to ask Slurm for. Partition, time and memory are per stage:
// "VALUE" for every stage, or "VALUE,train=OTHER,export=..." (an entry
// without '=' is the default of the stages not named); empty: Slurm's default.
struct SlurmOptions {
  std::string partition;   // --partition per stage
  std::string time;        // --time per stage (Slurm's forms: MINUTES, H:MM:SS, D-HH)
  std::string mem;         // --mem per stage (4G)
  std::string gres;        // --gres of the train stage (gpu:1)
  int cpus_per_task = 0;   // --cpus-per-task of every stage; 0: Slurm's default
  int max_parallel = 0;    // captures of one stage running at once (--array=...%N); 0: no limit
  int signal_seconds = 120;  // --signal=B:TERM@seconds: the warning before the time limit

  Status Check(const std::vector<std::string>& stages) const;
};

// One submitted (or planned) batch, as DIR/.batch/<id>/batch.json keeps it.
struct BatchPlan {
  std::string id;                   // the batch's folder name under ROOT/.batch
  fs::path root;                    // absolute; captures' workspaces are ROOT/<name>
  std::string headforge;            // the binary the jobs run
  std::vector<std::string> stages;  // in order, the last one the batch runs up to
  std::vector<BatchRow> rows;       // array index i is rows[i]
  SlurmOptions slurm;
  std::map<std::string, std::string> job_ids;  // stage -> its array's job id (after submission)

  fs::path Dir() const { return root / ".batch" / id; }
  fs::path Log(const std::string& stage, size_t index) const;
  // The arguments of the headforge the job of `stage` runs for rows[index].
  std::vector<std::string> StageArgs(const std::string& stage, size_t index) const;
  // sbatch's arguments for `stage` (`after`: the previous stage's job id, or "").
  std::vector<std::string> SbatchArgs(const std::string& stage, const std::string& after) const;
  // The job script of `stage`: it only execs `headforge batch job DIR STAGE`.
  std::string Script(const std::string& stage) const;
};

Status WriteBatchPlan(const BatchPlan& plan);
Status ReadBatchPlan(const fs::path& batch_dir, BatchPlan* plan);
// The newest batch under ROOT/.batch (ids sort by time).
Status LatestBatch(const fs::path& root, fs::path* batch_dir);

// `text` quoted for a POSIX shell, for display (dry runs, logs).
std::string ShellQuote(const std::string& text);

// Writes the scripts and batch.json into plan->Dir() and submits one array
// per stage, recording their ids. A refused sbatch cancels the arrays
// already submitted. `dry_run`: writes nothing, prints what it would submit.
Status SubmitBatch(BatchPlan* plan, bool dry_run, std::ostream& out);

// One array element's state in `squeue --states=all` ("PENDING",
// "RUNNING", "COMPLETED", "CANCELLED", ... with squeue's reason).
struct QueueState {
  std::string state;
  std::string reason;
};
// squeue's states of the batch's jobs by "<jobid>_<index>"; empty when
// squeue knows none of them (gone from its memory, or no squeue).
Status QueryQueue(const BatchPlan& plan, std::map<std::string, QueueState>* states);

// `headforge batch status`: each capture's stages from its workspace and the
// queue. Prints a table (or JSON when `json`); *failed is true when a stage
// failed or was cancelled, *settled when no job is pending or running.
Status ReportBatch(const BatchPlan& plan, bool json, std::ostream& out, bool* failed, bool* settled);

// `headforge batch job`: runs rows[index]'s `stage` as a child headforge,
// forwarding SIGTERM and SIGINT to it. Returns the exit code: the child's,
// or kBatchExitInterrupted after a signal (the job then requeued itself
// when it runs under Slurm).
int RunBatchJob(const BatchPlan& plan, const std::string& stage, size_t index);

}  // namespace headforge
