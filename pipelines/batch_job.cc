// `headforge batch job` (one array element's stage) and `headforge batch
// status` (the captures' stages from their workspaces and squeue).
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iomanip>
#include <ostream>

#include "core/json_io.h"
#include "core/process.h"
#include "core/workspace.h"
#include "pipelines/batch_slurm.h"

extern char** environ;

namespace headforge {
namespace {

volatile sig_atomic_t g_child = 0;   // the stage's process, once started
volatile sig_atomic_t g_signal = 0;  // the first SIGTERM or SIGINT received

// Every signal goes on to the stage (a resumable one checkpoints on the
// first); this process only remembers that one came, to requeue.
void Forward(int signal) {
  if (g_signal == 0) g_signal = signal;
  if (g_child > 0) ::kill(static_cast<pid_t>(g_child), signal);
}

std::string Env(const char* name) {
  const char* value = std::getenv(name);
  return value ? value : "";
}

// Starts `args` (args[0] a path) with this process's stdout and stderr, and
// waits for it, forwarding SIGTERM and SIGINT. Its exit code, or 128 + the
// signal that ended it, or -1 when it could not start; its CPU time in *cpu_s.
int SpawnForwarding(const std::vector<std::string>& args, double* cpu_s) {
  g_signal = 0;
  struct sigaction action {}, previous_term {}, previous_int {};
  action.sa_handler = Forward;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGTERM, &action, &previous_term);
  sigaction(SIGINT, &action, &previous_int);
  const auto restore = [&] {
    sigaction(SIGTERM, &previous_term, nullptr);
    sigaction(SIGINT, &previous_int, nullptr);
  };
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  // posix_spawn resets caught signals to their defaults in the child.
  if (const int e = ::posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ); e != 0) {
    std::fprintf(stderr, "headforge batch: cannot start %s: %s\n", argv[0], std::strerror(e));
    restore();
    return -1;
  }
  g_child = pid;
  if (g_signal != 0) ::kill(pid, g_signal);  // it came before the child had a pid
  int status = 0;
  rusage usage{};
  while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  *cpu_s = usage.ru_utime.tv_sec + usage.ru_stime.tv_sec + 1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  g_child = 0;
  restore();
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// After a signal, under Slurm: this array element back in the queue. Slurm
// ends this job then, and holds the requeued one about two minutes (its
// BeginTime) before it may start again.
void Requeue(const fs::path& log) {
  const std::string job = Env("SLURM_ARRAY_JOB_ID"), task = Env("SLURM_ARRAY_TASK_ID");
  if (job.empty() || task.empty()) {
    std::printf("headforge batch: not under Slurm: not requeued; submit again to resume\n");
    return;
  }
  const std::string element = job + "_" + task;
  std::printf("headforge batch: requeueing job %s\n", element.c_str());
  std::fflush(stdout);
  int code = 0;
  if (!RunProgram({"scontrol", "requeue", element}, log, &code).ok() || code != 0) {
    std::printf("headforge batch: scontrol requeue %s failed; submit the batch again to resume\n", element.c_str());
  }
}

bool Active(const std::string& state) {
  return state == "PENDING" || state == "RUNNING" || state == "CONFIGURING" || state == "COMPLETING" ||
         state == "REQUEUED" || state == "REQUEUE_HOLD" || state == "REQUEUE_FED" || state == "SUSPENDED" ||
         state == "RESIZING" || state == "SIGNALING" || state == "STAGE_OUT";
}

struct StageView {
  std::string state;   // done, running, pending, failed, cancelled, interrupted, not run, ...
  std::string reason;  // squeue's reason, or the workspace's failure message
  bool failed = false;
  bool active = false;
};

StageView ViewOf(const Workspace* workspace, const std::string& stage, const QueueState* queued) {
  StageView view;
  const StageRecord* record = workspace ? workspace->Find(stage) : nullptr;
  if (queued && Active(queued->state)) {
    view.active = true;
    view.state = queued->state == "PENDING" ? "pending" : queued->state == "RUNNING" ? "running" : queued->state;
    if (queued->reason != "None") view.reason = queued->reason;
    return view;
  }
  if (queued && queued->state == "CANCELLED") {
    view = {"cancelled", queued->reason, true, false};
    return view;
  }
  if (record && record->status == StageStatus::kDone && workspace->OutOfDate(stage).empty()) {
    view.state = "done";
  } else if (record && record->status == StageStatus::kFailed) {
    view = {"failed", record->message, true, false};
  } else if (queued && queued->state != "COMPLETED") {
    view = {"failed", queued->state + (queued->reason == "None" ? "" : " " + queued->reason), true, false};
  } else {
    view.state = record ? StageStatusName(record->status) : "not run";
  }
  return view;
}

}  // namespace

int RunBatchJob(const BatchPlan& plan, const std::string& stage, size_t index) {
  const BatchRow& row = plan.rows.at(index);
  const std::string restarts = Env("SLURM_RESTART_COUNT");
  std::printf("headforge batch %s: capture '%s' (manifest line %d), stage %s, attempt %d\n", plan.id.c_str(),
              row.name.c_str(), row.line, stage.c_str(), restarts.empty() ? 1 : std::atoi(restarts.c_str()) + 1);
  std::vector<std::string> args = plan.StageArgs(stage, index);
  args.insert(args.begin(), plan.headforge);
  std::printf("headforge batch: runs %s\n", nlohmann::json(args).dump().c_str());
  std::fflush(stdout);
  // One thread per CPU Slurm gave the job, not one per core of the node.
  if (!Env("SLURM_CPUS_PER_TASK").empty() && Env("HEADFORGE_THREADS").empty())
    ::setenv("HEADFORGE_THREADS", Env("SLURM_CPUS_PER_TASK").c_str(), 1);
  const auto start = std::chrono::steady_clock::now();
  double cpu_s = 0;
  const int code = SpawnForwarding(args, &cpu_s);
  std::printf("headforge batch: stage %s of '%s' exited %d after %.1f s (%.1f s of CPU)\n", stage.c_str(),
              row.name.c_str(), code, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
              cpu_s);
  if (g_signal != 0 && code != 0) {
    std::printf("headforge batch: stage %s of '%s' stopped by signal %d (exit %d)\n", stage.c_str(), row.name.c_str(),
                static_cast<int>(g_signal), code);
    Requeue(plan.Log(stage, index));
    std::fflush(stdout);
    return kBatchExitInterrupted;
  }
  if (code == 0) return 0;
  std::printf("headforge batch: capture '%s' failed at %s (exit %d); log: %s\n", row.name.c_str(), stage.c_str(), code,
              plan.Log(stage, index).c_str());
  std::fflush(stdout);
  return code > 0 && code < 126 ? code : 1;
}

Status ReportBatch(const BatchPlan& plan, bool json, std::ostream& out, bool* failed, bool* settled) {
  std::map<std::string, QueueState> queue;
  HF_RETURN_IF_ERROR(QueryQueue(plan, &queue));
  *failed = false;
  *settled = true;
  nlohmann::json captures = nlohmann::json::array();
  for (size_t i = 0; i < plan.rows.size(); ++i) {
    const BatchRow& row = plan.rows[i];
    std::unique_ptr<Workspace> workspace;
    if (Workspace::Exists(plan.root / row.name))
      (void)Workspace::Open(plan.root / row.name, Workspace::Mode::kReadOnly, &workspace);
    nlohmann::json stages = nlohmann::json::array();
    for (const auto& stage : plan.stages) {
      const auto it = plan.job_ids.find(stage);
      const auto q = it == plan.job_ids.end() ? queue.end() : queue.find(it->second + "_" + std::to_string(i));
      const StageView view = ViewOf(workspace.get(), stage, q == queue.end() ? nullptr : &q->second);
      *failed = *failed || view.failed;
      *settled = *settled && !view.active;
      nlohmann::json s = {{"stage", stage}, {"state", view.state}, {"reason", view.reason}};
      if (view.state == "failed") s["log"] = plan.Log(stage, i).string();
      stages.push_back(s);
    }
    captures.push_back({{"name", row.name}, {"line", row.line}, {"stages", stages}});
  }
  if (json) {
    out << nlohmann::json({{"batch", plan.id}, {"root", plan.root.string()}, {"settled", *settled},
                           {"failed", *failed}, {"captures", captures}})
               .dump(1)
        << "\n";
    return Status::Ok();
  }
  out << "batch " << plan.id << " (" << plan.Dir().string() << ")\n" << std::left << std::setw(24) << "capture";
  for (const auto& stage : plan.stages) out << " " << std::setw(11) << stage;
  out << "\n";
  for (const auto& c : captures) {
    out << std::setw(24) << c["name"].get<std::string>();
    for (const auto& s : c["stages"]) out << " " << std::setw(11) << s["state"].get<std::string>();
    out << "\n";
  }
  for (const auto& c : captures)
    for (const auto& s : c["stages"])
      if (s.contains("log"))
        out << c["name"].get<std::string>() << ": " << s["stage"].get<std::string>() << " "
            << s["state"].get<std::string>() << (s["reason"].get<std::string>().empty() ? "" : " (")
            << s["reason"].get<std::string>() << (s["reason"].get<std::string>().empty() ? "" : ")")
            << "; log: " << s["log"].get<std::string>() << "\n";
  return Status::Ok();
}

}  // namespace headforge
