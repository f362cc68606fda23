// `headforge batch`: many captures as jobs of a cluster scheduler (Slurm).
#include <cstdio>
#include <ctime>
#include <iostream>

#include "core/log.h"
#include "pipelines/batch_slurm.h"
#include "pipelines/commands.h"
#include "pipelines/stage_table.h"

namespace headforge {
namespace {

const std::vector<std::string> kPresets = {"draft", "standard", "high"};

// A new batch id: the UTC time, then a number free under ROOT/.batch.
std::string NewBatchId(const fs::path& root) {
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::strftime(stamp, sizeof(stamp), "%Y%m%d-%H%M%S", &utc);
  for (int n = 0;; ++n) {
    char id[48];
    std::snprintf(id, sizeof(id), "%s-%02d", stamp, n);
    std::error_code ec;
    if (!fs::exists(root / ".batch" / id, ec)) return id;
  }
}

std::string SelfPath() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? "headforge" : self.string();
}

// The stages of the table up to `until`, in order.
Status StagesUntil(const std::string& until, std::vector<std::string>* stages) {
  stages->clear();
  for (const StageEntry& e : StageTable()) {
    if (!e.unavailable.empty() || !e.make) break;
    stages->push_back(e.name);
    if (e.name == until) return Status::Ok();
  }
  if (until.empty()) return Status::Ok();
  return Status::InvalidArgument("--until: no stage named '" + until + "' that this version runs");
}

// Refuses a submission while the root's last batch still has jobs queued:
// two jobs on one workspace would meet at its lock.
Status CheckNothingQueued(const fs::path& root) {
  fs::path last;
  BatchPlan previous;
  if (!LatestBatch(root, &last).ok() || !ReadBatchPlan(last, &previous).ok()) return Status::Ok();
  std::map<std::string, QueueState> queue;
  if (!QueryQueue(previous, &queue).ok()) return Status::Ok();
  for (const auto& [element, state] : queue)
    if (state.state == "PENDING" || state.state == "RUNNING" || state.state == "REQUEUED")
      return Status::InvalidArgument("batch " + previous.id + " still has job " + element + " " + state.state +
                                     " on these workspaces; wait for it (headforge batch status) or scancel it");
  return Status::Ok();
}

int SubmitCommand(const std::vector<std::string>& args) {
  OptionSet options;
  std::string manifest, root, scheduler = "slurm", until;
  bool dry_run = false;
  BatchPlan plan;
  SlurmOptions& slurm = plan.slurm;
  constexpr auto kRuntime = OptionSet::Effect::kRuntime;
  options.AddPositional("MANIFEST", &manifest, "The manifest: one capture per row (docs/cluster.md).");
  options.Add("root", &root, "The folder of the captures' workspaces (ROOT/<name>) and of the batch's files.", "", kRuntime);
  options.Add("scheduler", &scheduler, "The cluster's scheduler: slurm.", "", kRuntime);
  options.Add("until", &until, "The last stage to run (default: every stage this version runs).", "", kRuntime);
  options.Add("dry_run", &dry_run, "Print the job scripts, sbatch commands and each job's arguments; submit nothing.",
              "dry-run", kRuntime);
  options.Add("max_parallel", &slurm.max_parallel, "Captures of one stage running at once; 0: no limit.", "max-parallel",
              kRuntime);
  options.Add("partition", &slurm.partition, "Partition: NAME for every stage, or NAME,train=GPU_PARTITION,...", "",
              kRuntime);
  options.Add("time", &slurm.time, "Time limit per job: 2:00:00, or 1:00:00,train=24:00:00,...", "", kRuntime);
  options.Add("mem", &slurm.mem, "Memory per job: 8G, or 8G,train=32G,...", "", kRuntime);
  options.Add("gres", &slurm.gres, "Generic resources of the train jobs (gpu:1).", "", kRuntime);
  options.Add("cpus_per_task", &slurm.cpus_per_task, "CPUs per job (headforge runs one thread each); 0: Slurm's default.",
              "cpus-per-task", kRuntime);
  options.Add("signal_seconds", &slurm.signal_seconds,
              "SIGTERM this many seconds before a job's time limit (--signal=B:TERM@N): the stage checkpoints or "
              "stops, and the job requeues itself; 0: none.",
              "signal-seconds", kRuntime);
  const int parsed = ParseOrExit(
      &options, args, "headforge batch submit MANIFEST --root DIR --scheduler slurm [options]",
      "Submits every capture of the manifest as one job array per stage: element i of a stage waits for element i\n"
      "of the stage before (--dependency=aftercorr), so one capture's failure cancels only its own later stages.\n"
      "Job scripts and logs go to DIR/.batch/<id>/. Submitted again, each job skips what is done and up to date.");
  if (parsed >= 0) return parsed;
  if (manifest.empty()) return ReportFailure(Status::InvalidArgument("batch submit: give the MANIFEST"));
  if (root.empty()) return ReportFailure(Status::InvalidArgument("batch submit: give --root DIR"));
  if (scheduler != "slurm")
    return ReportFailure(Status::InvalidArgument("batch submit: --scheduler " + scheduler + ": only slurm is known"));
  if (Status s = StagesUntil(until, &plan.stages); !s.ok()) return ReportFailure(s);
  if (Status s = slurm.Check(plan.stages); !s.ok()) return ReportFailure(s.WithContext("batch submit"));
  if (Status s = ReadManifest(manifest, kPresets, &plan.rows); !s.ok()) return ReportFailure(s);
  plan.root = AbsolutePath(fs::absolute(root));
  plan.id = NewBatchId(plan.root);
  plan.headforge = SelfPath();
  if (!dry_run)
    if (Status s = CheckNothingQueued(plan.root); !s.ok()) return ReportFailure(s.WithContext("batch submit"));
  if (Status s = SubmitBatch(&plan, dry_run, std::cout); !s.ok()) return ReportFailure(s);
  return kExitOk;
}

int BatchStatusCommand(const std::vector<std::string>& args) {
  OptionSet options;
  std::string root, batch;
  bool json = false;
  options.AddPositional("DIR", &root, "The batch's root folder (--root of batch submit).");
  options.Add("batch", &batch, "The batch id (a folder of DIR/.batch); default: the latest.", "", OptionSet::Effect::kRuntime);
  options.Add("json", &json, "Print JSON, for scripts.", "", OptionSet::Effect::kRuntime);
  const int parsed = ParseOrExit(
      &options, args, "headforge batch status DIR [--batch ID] [--json]",
      "Shows each capture's stages from its workspace and squeue (no accounting needed): done, pending, running,\n"
      "failed (with the job's log) or cancelled (an earlier stage of the capture failed).\n"
      "Exit codes: 0 nothing failed (yet), 1 a stage failed or was cancelled.");
  if (parsed >= 0) return parsed;
  if (root.empty()) return ReportFailure(Status::InvalidArgument("batch status: give the DIR"));
  fs::path dir = fs::path(root) / ".batch" / batch;
  if (batch.empty())
    if (Status s = LatestBatch(root, &dir); !s.ok()) return ReportFailure(s);
  BatchPlan plan;
  if (Status s = ReadBatchPlan(dir, &plan); !s.ok()) return ReportFailure(s);
  bool failed = false, settled = false;
  if (Status s = ReportBatch(plan, json, std::cout, &failed, &settled); !s.ok()) return ReportFailure(s);
  return failed ? kExitFailure : kExitOk;
}

int BatchJobCommand(const std::vector<std::string>& args) {
  OptionSet options;
  std::string dir, stage;
  int index = -1;
  options.AddPositional("BATCH_DIR", &dir, "The batch's folder (ROOT/.batch/<id>).");
  options.AddPositional("STAGE", &stage, "The stage this job runs.");
  options.Add("index", &index, "The capture's row in batch.json; default: $SLURM_ARRAY_TASK_ID.", "",
              OptionSet::Effect::kRuntime);
  const int parsed = ParseOrExit(&options, args, "headforge batch job BATCH_DIR STAGE [--index I]",
                                 "Runs one capture's stage of a submitted batch (what its job scripts run). Exit codes: "
                                 "the stage's,\nor 75 when a signal stopped it (the job then requeued itself).");
  if (parsed >= 0) return parsed;
  BatchPlan plan;
  if (Status s = ReadBatchPlan(dir, &plan); !s.ok()) return ReportFailure(s);
  if (index < 0 && std::getenv("SLURM_ARRAY_TASK_ID")) index = std::atoi(std::getenv("SLURM_ARRAY_TASK_ID"));
  if (index < 0 || static_cast<size_t>(index) >= plan.rows.size())
    return ReportFailure(Status::InvalidArgument("batch job: no capture " + std::to_string(index) + " in " + dir));
  if (std::find(plan.stages.begin(), plan.stages.end(), stage) == plan.stages.end())
    return ReportFailure(Status::InvalidArgument("batch job: " + stage + " is not a stage of batch " + plan.id));
  return RunBatchJob(plan, stage, static_cast<size_t>(index));
}

}  // namespace

int BatchCommand(const std::vector<std::string>& args) {
  const std::string what = args.empty() ? "" : args[0];
  const std::vector<std::string> rest(args.begin() + (args.empty() ? 0 : 1), args.end());
  if (what == "submit") return SubmitCommand(rest);
  if (what == "status") return BatchStatusCommand(rest);
  if (what == "job") return BatchJobCommand(rest);
  const bool help = what == "--help" || what == "-h";
  std::fprintf(help ? stdout : stderr,
               "Usage: headforge batch submit MANIFEST --root DIR --scheduler slurm [options]\n"
               "       headforge batch status DIR [--json]\n"
               "       headforge batch job BATCH_DIR STAGE   (what the job scripts run)\n"
               "Each takes --help. docs/cluster.md: the manifest, the options, exit codes, requeue.\n");
  return help ? kExitOk : kExitUsage;
}

}  // namespace headforge
