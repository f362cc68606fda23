// `headforge batch` on a real one-node Slurm (22.05, Debian's packages from
// scripts/install_deps.sh) brought up on localhost for the test: munged as
// the munge user with its own key and socket, slurmctld and slurmd as root on
// ports of their own, every file under the test's temporary folder; the
// daemons are stopped by their pids at the end, also when the test fails.
// A batch of three tiny simulated captures (one named with quotes, ';' and
// $(...)) plus one whose video is damaged, up to a tiny training: each
// capture's stages run in order; the damaged one fails at ingest and only its
// later stages are cancelled; a train job given SIGTERM checkpoints, requeues
// itself and resumes; the same manifest submitted again skips everything.
// Needs root (slurmd and SlurmUser=root).
#include <gtest/gtest.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <functional>
#include <thread>

#include "core/json_io.h"
#include "core/process.h"
#include "tests/free_port.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

using Clock = std::chrono::steady_clock;
const std::string kOdd = "it's \"odd\"; $(touch pwned) b";
const std::vector<std::string> kStages = {"ingest", "calibrate", "align", "track", "train"};
// The headforge the batch runs: a copy of the build's, which a rebuild while
// the batch runs would otherwise replace under jobs starting it.
std::string g_headforge = HEADFORGE_BINARY;

Result Hf(const std::vector<std::string>& args) { return Headforge(args, g_headforge.c_str()); }

// `args`' output (stdout and stderr), and its exit code in *code.
std::string Output(const std::vector<std::string>& args, int* code = nullptr) {
  const fs::path log = fs::temp_directory_path() / ("hf_slurm_out_" + std::to_string(::getpid()));
  fs::remove(log);
  int exit_code = -1;
  const Status s = RunProgram(args, log, &exit_code);
  if (code) *code = s.ok() ? exit_code : -1;
  std::string text = Slurp(log);
  fs::remove(log);
  return s.ok() ? text : s.message();
}

// Polls `done` every `every` until it holds or `limit` passes.
bool WaitFor(const std::function<bool()>& done, std::chrono::seconds limit,
             std::chrono::milliseconds every = std::chrono::milliseconds(200)) {
  const auto end = Clock::now() + limit;
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(every);
  }
  return done();
}

// A one-node Slurm cluster under `dir`, up from construction (error empty)
// to destruction.
class OneNodeSlurm {
 public:
  explicit OneNodeSlurm(const fs::path& dir) : dir_(dir) { error = Start(); }
  ~OneNodeSlurm() { Stop(); }
  std::string error;

 private:
  std::string Start() {
    const passwd* munge = ::getpwnam("munge");
    if (!munge) return "no munge user: install munge (scripts/install_deps.sh)";
    fs::create_directories(dir_ / "munge");
    fs::create_directories(dir_ / "state");
    fs::create_directories(dir_ / "spool");
    const fs::path key = dir_ / "munge" / "munge.key";
    int code = 0;
    const std::string made = Output({"mungekey", "--create", "--keyfile", key.string(), "--force"}, &code);
    if (code != 0) return "mungekey failed: " + made;
    for (const fs::path& p : {dir_ / "munge", key})
      if (::chown(p.c_str(), munge->pw_uid, munge->pw_gid) != 0) return "cannot chown " + p.string();
    const fs::path munge_dir = dir_ / "munge";
    const std::string said = Output({"runuser", "-u", "munge", "--", "munged", "--force", "--socket=" + (munge_dir / "sock").string(),
                                     "--key-file=" + key.string(), "--pid-file=" + (munge_dir / "munged.pid").string(),
                                     "--log-file=" + (munge_dir / "munged.log").string(),
                                     "--seed-file=" + (munge_dir / "munged.seed").string()},
                                    &code);
    if (code != 0) return "munged did not start: " + said;
    const std::string node = Output({"slurmd", "-C"}, &code);
    if (code != 0 || node.rfind("NodeName=", 0) != 0) return "slurmd -C: " + node;
    char host[256] = {};
    ::gethostname(host, sizeof(host) - 1);
    const std::string conf = std::string("ClusterName=hftest\nSlurmctldHost=") + host + "(127.0.0.1)\n" +
        "SlurmUser=root\nSlurmctldPort=" + std::to_string(FreePort()) + "\nSlurmdPort=" + std::to_string(FreePort()) +
        "\nAuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket=" + (munge_dir / "sock").string() +
        "\nStateSaveLocation=" + (dir_ / "state").string() + "\nSlurmdSpoolDir=" + (dir_ / "spool").string() +
        "\nSlurmctldPidFile=" + (dir_ / "slurmctld.pid").string() + "\nSlurmdPidFile=" + (dir_ / "slurmd.pid").string() +
        "\nSlurmctldLogFile=" + (dir_ / "slurmctld.log").string() + "\nSlurmdLogFile=" + (dir_ / "slurmd.log").string() +
        "\nProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nJobAcctGatherType=jobacct_gather/none\n"
        "AccountingStorageType=accounting_storage/none\nJobCompType=jobcomp/none\nSelectType=select/cons_tres\n"
        "SelectTypeParameters=CR_Core\nReturnToService=2\nMpiDefault=none\nKillWait=5\nMinJobAge=900\n"
        // A job whose dependency is met starts at once, not at the scheduler's
        // next batch tick (3 s by default: on this chain of short stages, a
        // third of the batch's time).
        "SchedulerParameters=batch_sched_delay=0\n" +
        node.substr(0, node.find('\n')) + " NodeAddr=127.0.0.1 State=UNKNOWN\n" +
        "PartitionName=cpu Nodes=" + host + " Default=YES MaxTime=INFINITE State=UP\n"
        "PartitionName=gpu Nodes=" + host + " MaxTime=INFINITE State=UP\n";
    if (!WriteFileAtomic(dir_ / "slurm.conf", conf).ok()) return "cannot write slurm.conf";
    ::setenv("SLURM_CONF", (dir_ / "slurm.conf").c_str(), 1);
    for (const char* daemon : {"slurmctld", "slurmd"}) {
      const std::vector<std::string> args =
          daemon == std::string("slurmctld") ? std::vector<std::string>{"slurmctld", "-i"} : std::vector<std::string>{"slurmd"};
      const std::string started = Output(args, &code);
      if (code != 0) return std::string(daemon) + " did not start: " + started + Slurp(dir_ / (std::string(daemon) + ".log"));
    }
    if (!WaitFor([] { return Output({"sinfo", "--noheader", "--format=%t"}).find("idle") != std::string::npos; },
                 std::chrono::seconds(30)))
      return "the node is not idle after 30 s: " + Output({"sinfo"}) + Slurp(dir_ / "slurmctld.log");
    return "";
  }

  void StopPid(const fs::path& pid_file) {
    const pid_t pid = std::atoi(Slurp(pid_file).c_str());
    if (pid <= 0) return;
    ::kill(pid, SIGTERM);
    if (!WaitFor([pid] { return ::kill(pid, 0) != 0; }, std::chrono::seconds(15))) ::kill(pid, SIGKILL);
  }

  void Stop() {
    if (fs::exists(dir_ / "slurmctld.pid")) {
      Output({"scancel", "--user=root"});
      WaitFor([] { return Output({"squeue", "--noheader", "--states=RUNNING"}).empty(); }, std::chrono::seconds(20));
    }
    StopPid(dir_ / "slurmd.pid");
    StopPid(dir_ / "slurmctld.pid");
    StopPid(dir_ / "munge" / "munged.pid");
  }

  fs::path dir_;
};

nlohmann::json BatchStatus(const fs::path& root) {
  const Result r = Hf({"batch", "status", root.string(), "--json"});
  try {
    return nlohmann::json::parse(r.out);
  } catch (const std::exception&) {
    ADD_FAILURE() << "batch status --json: " << r.out << r.err;
    return {};
  }
}

// Waits for the root's latest batch to have no job pending or running.
// While Slurm still queues a job of this cluster's (squeue, a small
// program) the batch has not settled; `batch status` (a LibTorch program:
// 0.45 s of CPU a start, taken from the test running beside this one) is
// asked once the queue is empty, and again until it says settled.
nlohmann::json Settled(const fs::path& root, std::chrono::seconds limit) {
  const auto end = Clock::now() + limit;
  WaitFor([] {
    int code = 0;
    const std::string queued = Output({"squeue", "--noheader"}, &code);
    return code != 0 || queued.empty();
  }, limit, std::chrono::seconds(1));
  nlohmann::json status;
  const bool settled = WaitFor([&] {
    status = BatchStatus(root);
    return status.value("settled", false);
  }, std::max(std::chrono::duration_cast<std::chrono::seconds>(end - Clock::now()), std::chrono::seconds(0)),
     std::chrono::seconds(2));
  EXPECT_TRUE(settled) << "the batch did not settle in " << limit.count() << " s: " << status.dump(1)
                       << Output({"squeue", "--states=all", "--array"});
  return status;
}

std::map<std::string, std::string> States(const nlohmann::json& status, const std::string& capture) {
  std::map<std::string, std::string> states;
  for (const auto& c : status.value("captures", nlohmann::json::array()))
    if (c["name"] == capture)
      for (const auto& s : c["stages"]) states[s["stage"]] = s["state"];
  return states;
}

// "train: job array 12" in batch submit's output.
std::string ArrayId(const std::string& said, const std::string& stage) {
  const size_t at = said.find(stage + ": job array ");
  if (at == std::string::npos) return "";
  const size_t start = at + stage.size() + 12;
  return said.substr(start, said.find('\n', start) - start);
}

fs::path BatchDir(const fs::path& root, const std::string& said) {
  const size_t at = said.find("logs in ");
  return fs::path(said.substr(at + 8, said.find(';', at) - at - 8)).parent_path();
}

// Three tiny captures of one 12-frame simulation (a 30-step training; 150
// for "slow", to be stopped midway) and a damaged video, in dir/manifest.tsv.
void WriteCaptures(const fs::path& dir) {
  const std::string input = SimulatedInputs(SharedSimulation("talking_static", 12)).at(0);
  const std::string tiny_steps = "[train]\nsteps = 30\n";
  const std::string tiny_rest =
      "resolution = 48\ncanonical_fraction = 0.5\ninit_gaussians = 600\nmax_gaussians = 800\n"
      "densify_from = 10\ndensify_every = 10\ndensify_until = 20\neval_every = 0\npreview_every = 0\nlog_every = 10\n"
      "checkpoint_every = 5\nmax_minutes = 0\n";
  EXPECT_TRUE(WriteFileAtomic(dir / "tiny.ini", tiny_steps + tiny_rest).ok());
  // Long enough to be stopped midway, by a checkpoint every 5 steps.
  EXPECT_TRUE(WriteFileAtomic(dir / "slow.ini", "[train]\nsteps = 150\n" + tiny_rest).ok());
  std::string noise(20000, '\0');
  for (size_t i = 0; i < noise.size(); ++i) noise[i] = static_cast<char>((i * 2654435761u) >> 13);
  EXPECT_TRUE(WriteFileAtomic(dir / "damaged.mp4", noise).ok());
  const std::string manifest = "# name\tpreset\tconfig\tvideo\nalpha\tdraft\ttiny.ini\t" + input + "\n" + kOdd +
                               "\t\ttiny.ini\t" + input + "\nslow\tdraft\tslow.ini\t" + input +
                               "\nbroken\tdraft\ttiny.ini\tdamaged.mp4\n";
  EXPECT_TRUE(WriteFileAtomic(dir / "manifest.tsv", manifest).ok());
}

TEST(Slurm, BatchOfCapturesRunsInOrderFailsAloneRequeuesAndSkipsWhatIsDone) {
  ASSERT_EQ(::geteuid(), 0u) << "slurm_test needs root: it starts munged, slurmctld and slurmd (a one-node Slurm)";
  for (const char* tool : {"slurmctld", "slurmd", "munged", "mungekey", "sbatch", "squeue", "scontrol", "runuser"})
    ASSERT_EQ(std::system((std::string("command -v ") + tool + " >/dev/null").c_str()), 0)
        << tool << " is not installed: scripts/install_deps.sh installs Slurm and munge";
  const fs::path dir = fs::temp_directory_path() / ("hf_slurm_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  WriteCaptures(dir);
  g_headforge = (dir / "headforge").string();
  fs::copy_file(HEADFORGE_BINARY, g_headforge);
  const fs::path root = dir / "root";
  const std::vector<std::string> submit = {"batch", "submit", (dir / "manifest.tsv").string(), "--root", root.string(),
                                           "--scheduler", "slurm", "--until", "train", "--cpus-per-task", "1"};

  // The test's folder goes once the cluster has stopped, when the test passed.
  struct RemoveIfPassed {
    fs::path dir;
    ~RemoveIfPassed() {
      if (!::testing::Test::HasFailure()) fs::remove_all(dir);
    }
  } cleanup{dir};
  OneNodeSlurm cluster(dir / "cluster");
  ASSERT_EQ(cluster.error, "");
  const auto start = Clock::now();
  const Result first = Hf(submit);
  ASSERT_EQ(first.code, 0) << first.out << first.err;
  const std::string train = ArrayId(first.out, "train");
  ASSERT_FALSE(train.empty()) << first.out;

  // SIGTERM to the slow capture's train job (as --signal=B:TERM sends it)
  // once it has a checkpoint; released from Slurm's requeue hold once queued.
  const fs::path checkpoint = root / "slow" / ".staging" / "train" / "models" / "gaussian_style" / "checkpoint.pt";
  const fs::path batch = BatchDir(root, first.out);
  const auto slow_failed = [&] {  // its train element cancelled: an earlier stage failed
    const std::string job = Output({"squeue", "--noheader", "--array", "--states=all", "--jobs=" + train, "--format=%i %T"});
    return job.find(train + "_2 CANCELLED") != std::string::npos || job.find(train + "_2 FAILED") != std::string::npos;
  };
  ASSERT_TRUE(WaitFor([&] { return fs::exists(checkpoint) || slow_failed(); }, std::chrono::seconds(240)) &&
              !slow_failed())
      << "no checkpoint of slow's training: " << BatchStatus(root).dump(1);
  Output({"scancel", "--signal=TERM", "--batch", train + "_2"});
  ASSERT_TRUE(WaitFor([&] {
    const std::string job = Output({"scontrol", "show", "job", train + "_2"});
    return job.find("JobState=PENDING") != std::string::npos && job.find("Restarts=1") != std::string::npos;
  }, std::chrono::seconds(60))) << Output({"scontrol", "show", "job", train + "_2"});
  // The requeue revoked the job's credential as of its second; a launch with
  // a credential made in that same second is refused ("Job credential
  // revoked") and the job ends failed. Slurm's own hold keeps them apart by
  // minutes; the release waits for the clock to pass that second.
  std::this_thread::sleep_for(std::chrono::milliseconds(2100));
  Output({"scontrol", "update", "JobId=" + train + "_2", "StartTime=now"});

  const nlohmann::json status = Settled(root, std::chrono::seconds(300));
  const double batch_s = std::chrono::duration<double>(Clock::now() - start).count();
  std::printf("the batch (4 captures, 5 stages, one requeue) settled in %.1f s\n", batch_s);
  EXPECT_TRUE(status.value("failed", false));
  for (const std::string name : {"alpha", kOdd.c_str(), "slow"}) {
    for (const auto& stage : kStages)
      EXPECT_EQ(States(status, name)[stage], "done") << name << " " << stage;
    // Each stage started after the one before it finished.
    nlohmann::json ws;
    ASSERT_TRUE(ReadJson(root / name / "workspace.json", &ws).ok()) << name;
    std::map<std::string, nlohmann::json> records;
    for (const auto& r : ws["stages"]) records[r["name"]] = r;
    for (size_t i = 1; i < kStages.size(); ++i)
      if (records.count(kStages[i - 1]) && records.count(kStages[i])) {
        EXPECT_LE(records[kStages[i - 1]].value("finished_at", "~"), records[kStages[i]].value("started_at", ""))
            << name << ": " << kStages[i] << " started before " << kStages[i - 1] << " finished";
      }
  }
  if (::testing::Test::HasFailure())
    std::printf("batch status: %s\nslurmctld.log:\n%s\n", status.dump(1).c_str(),
                Slurp(dir / "cluster" / "slurmctld.log").c_str());
  const auto broken = States(status, "broken");
  EXPECT_EQ(broken.at("ingest"), "failed");
  for (size_t i = 1; i < kStages.size(); ++i) EXPECT_EQ(broken.at(kStages[i]), "cancelled") << kStages[i];
  EXPECT_NE(Slurp(batch / "logs" / "ingest_3.log").find("capture 'broken' failed at ingest"), std::string::npos)
      << Slurp(batch / "logs" / "ingest_3.log");
  const Result table = Hf({"batch", "status", root.string()});
  EXPECT_EQ(table.code, 1);
  EXPECT_NE(table.out.find("broken: ingest failed"), std::string::npos) << table.out;
  EXPECT_NE(table.out.find((batch / "logs" / "ingest_3.log").string()), std::string::npos) << table.out;
  const std::string slow_log = Slurp(batch / "logs" / "train_2.log");
  EXPECT_NE(slow_log.find("requeueing job " + train + "_2"), std::string::npos) << slow_log;
  EXPECT_NE(slow_log.find("attempt 2"), std::string::npos) << slow_log;
  EXPECT_NE(slow_log.find("resuming from the checkpoint at step"), std::string::npos) << slow_log;
  EXPECT_TRUE(fs::exists(root / kOdd / "models" / "gaussian_style"));
  for (const fs::path& where : {dir, root, batch}) EXPECT_FALSE(fs::exists(where / "pwned")) << where;

  // The same manifest again: every stage of the good captures is skipped.
  std::map<std::string, std::string> before;
  for (const std::string name : {"alpha", kOdd.c_str(), "slow"}) before[name] = Slurp(root / name / "workspace.json");
  const auto again_start = Clock::now();
  const Result again = Hf(submit);
  ASSERT_EQ(again.code, 0) << again.out << again.err;
  const nlohmann::json second = Settled(root, std::chrono::seconds(240));
  std::printf("submitted again, it settled in %.1f s\n", std::chrono::duration<double>(Clock::now() - again_start).count());
  for (const auto& [name, record] : before) EXPECT_EQ(Slurp(root / name / "workspace.json"), record) << name;
  const fs::path batch2 = BatchDir(root, again.out);
  for (size_t i = 0; i < 3; ++i)
    for (const auto& stage : kStages) {
      const std::string log = Slurp(batch2 / "logs" / (stage + "_" + std::to_string(i) + ".log"));
      EXPECT_NE(log.find(stage + ": up to date (inputs and options unchanged), skipped"), std::string::npos) << log;
    }
  EXPECT_EQ(States(second, "broken").at("ingest"), "failed");
  EXPECT_EQ(States(second, "broken").at("train"), "cancelled");

  // One training over two ranks that srun starts in a job of two tasks:
  // Slurm's own variables (SLURM_PROCID, SLURM_STEP_NUM_TASKS) make them
  // ranks 0 and 1, and they train the model one process trains with both
  // views a step: headforge-train on a pack of alpha's capture, 20 steps at
  // 48 px, then headforge train on a copy of alpha's workspace with the
  // same options.
  const std::vector<std::string> options = {"--train-size", "48", "--steps", "20", "--triplane-resolution", "16", "--init-gaussians", "600",
                                            "--max-gaussians", "800", "--densify-from", "5", "--densify-every", "5",
                                            "--densify-until", "15", "--eval-every", "0", "--preview-every", "0",
                                            "--log-every", "5", "--checkpoint-every", "10", "--max-minutes", "0",
                                            "--decoder-steps", "0"};
  const fs::path pack = dir / "alpha.pack", alpha = dir / "alpha_ranks";
  std::vector<std::string> pack_args = {"pack", "--workspace", (root / "alpha").string(), "--out", pack.string()};
  pack_args.insert(pack_args.end(), options.begin(), options.end());
  const Result packed = Hf(pack_args);
  ASSERT_EQ(packed.code, 0) << packed.err;
  fs::copy(root / "alpha", alpha, fs::copy_options::recursive);
  const fs::path trainer = dir / "headforge-train";
  fs::copy_file(HEADFORGE_TRAIN_BINARY, trainer);
  const fs::path ranks = dir / "ranks", script = dir / "ranks.sh", log = dir / "ranks.log";
  // Its own port: the first step's store may still hold the job's.
  std::string on_workspace = "MASTER_PORT=" + std::to_string(FreePort()) + " exec srun " + g_headforge + " train --workspace " + alpha.string() + " --threads 1";
  for (const std::string& option : options) on_workspace += " " + option;
  ASSERT_TRUE(WriteFileAtomic(script, "#!/bin/sh\nsrun " + trainer.string() + " " + pack.string() + " --out " +
                                          ranks.string() + " --threads 1 || exit 1\n" + on_workspace + "\n")
                  .ok());
  // The node's name need not resolve on a test machine: rank 0 is reached at 127.0.0.1.
  int code = -1;
  const std::string submitted =
      Output({"sbatch", "--wait", "--ntasks", "2", "--cpus-per-task", "1", "--output", log.string(), "--export",
              "ALL,MASTER_ADDR=127.0.0.1,MASTER_PORT=" + std::to_string(FreePort()), script.string()},
             &code);
  const std::string said = Slurp(log);
  ASSERT_EQ(code, 0) << submitted << said;
  for (const char* line : {"headforge-train: rank 0 of 2 (slurm)", "headforge-train: rank 1 of 2 (slurm)",
                           "] train: rank 0 of 2 (slurm)", "] train: rank 1 of 2: trained stages 1-2 beside rank 0",
                           "data-parallel over 2 ranks, 2 training views"})
    EXPECT_NE(said.find(line), std::string::npos) << line << "\n" << said;
  const Result alone = Headforge({pack.string(), "--out", (dir / "alone").string(), "--threads", "1", "--set",
                                  "views_per_step=2"},
                                 trainer.c_str());
  ASSERT_EQ(alone.code, 0) << alone.err;
  EXPECT_EQ(FileHash(ranks / "model.pt"), FileHash(dir / "alone" / "model.pt"));
  EXPECT_EQ(FileHash(alpha / "models" / "gaussian_style" / "model.pt"), FileHash(dir / "alone" / "model.pt"));
}

}  // namespace
}  // namespace headforge
