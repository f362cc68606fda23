// Data-parallel training: headforge-train (and headforge train on a
// workspace) run as two ranks on this machine,
// each spawned as its own process with torchrun's variables (RANK,
// WORLD_SIZE, MASTER_ADDR, MASTER_PORT), on a training pack of the tracked
// capture. Two ranks with one view each per step train the model one
// process trains with both views per step, to the byte; a stop on one rank
// stops both at one step and the pair resumes to that same model; a rank
// that dies fails the other within its timeout; three ranks on three hosts
// (network namespaces joined by a bridge) meet and train it too.
#include <signal.h>
#include <sys/wait.h>

#include "tests/free_port.h"
#include "tests/train_fixture.h"

namespace headforge {
namespace {

// The run's exit code (128 + the signal that ended it).
int Wait(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

class DataParallel : public ::testing::Test {
 protected:
  // A pack of the tracked capture at 48 px: 40 steps of stages 1-2 (half
  // each), densification at steps 10, 20 and 30, a checkpoint every 5 steps;
  // then the two runs every test compares with.
  static void SetUpTestSuite() {
    dir_ = Scratch("data_parallel");
    pack_ = dir_ / "talking.pack";
    packed_ = Headforge({"pack", "--workspace", TrackedTalkingStatic().string(), "--out", pack_.string(),
                         "--train-size", "48", "--steps", "40", "--canonical-fraction", "0.5", "--triplane-resolution", "16", "--init-gaussians",
                         "1500", "--max-gaussians", "2500", "--densify-from", "10", "--densify-every", "10",
                         "--densify-until", "30", "--eval-every", "0", "--preview-every", "0", "--log-every", "5",
                         "--checkpoint-every", "5", "--max-minutes", "0", "--decoder-steps", "0"});
    if (packed_.code != 0) return;
    one_ = Headforge({pack_.string(), "--out", (dir_ / "one").string(), "--threads", "1", "--set", "views_per_step=2"},
                     HEADFORGE_TRAIN_BINARY);
    two_ = RunRanks(dir_ / "two");
  }

  // Rank `rank` of two (`out` beside its log), started now.
  static pid_t StartRank(int rank, int port, const fs::path& out, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args = {"RANK=" + std::to_string(rank), "WORLD_SIZE=2", "MASTER_ADDR=127.0.0.1",
                                     "MASTER_PORT=" + std::to_string(port), HEADFORGE_TRAIN_BINARY, pack_.string(),
                                     "--out", out.string(), "--threads", "1", "--distributed-timeout", "60"};
    args.insert(args.end(), extra.begin(), extra.end());
    const fs::path log = out.string() + ".rank" + std::to_string(rank) + ".log";
    return Spawn(args, log, log, "/usr/bin/env");
  }
  static std::string Log(const fs::path& out, int rank) {
    return Slurp(out.string() + ".rank" + std::to_string(rank) + ".log");
  }
  // Both ranks to the end; their exit codes.
  static std::pair<int, int> RunRanks(const fs::path& out) {
    const int port = FreePort();
    const pid_t zero = StartRank(0, port, out), one = StartRank(1, port, out);
    const int code_one = Wait(one);
    return {Wait(zero), code_one};
  }

  inline static fs::path dir_, pack_;
  inline static Result packed_, one_;
  inline static std::pair<int, int> two_;
};

TEST_F(DataParallel, TwoRanksTrainTheModelOneProcessTrainsWithBothViewsAStep) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  ASSERT_EQ(one_.code, 0) << one_.err;
  const fs::path two = dir_ / "two";
  ASSERT_EQ(two_.first, 0) << Log(two, 0);
  ASSERT_EQ(two_.second, 0) << Log(two, 1);
  EXPECT_NE(Log(two, 0).find("data-parallel over 2 ranks, 2 training views a step"), std::string::npos) << Log(two, 0);
  // Rank 0 wrote the model; both ranks' gradients went into every step: the
  // same bytes as one process taking both views (the sum of two numbers is
  // the same whichever rank holds which), densification included.
  EXPECT_EQ(FileHash(two / "model.pt"), FileHash(dir_ / "one" / "model.pt"));
  const std::vector<nlohmann::json> stats = StatsLines(two / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(dir_ / "one" / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  ASSERT_GE(stats.size(), 8u);
  for (size_t i = 0; i < stats.size(); ++i) {
    EXPECT_EQ(stats[i]["loss"], expected[i]["loss"]) << i;
    EXPECT_EQ(stats[i]["gaussians"], expected[i]["gaussians"]) << i;
  }
  EXPECT_NE(stats.front()["gaussians"], stats.back()["gaussians"]);  // densification ran
  nlohmann::json eval, expected_eval;
  ASSERT_TRUE(ReadJson(two / "eval.json", &eval).ok());
  ASSERT_TRUE(ReadJson(dir_ / "one" / "eval.json", &expected_eval).ok());
  EXPECT_EQ(eval["mean"]["psnr_masked"], expected_eval["mean"]["psnr_masked"]);
  // One view a step trains another model: the comparison can tell.
  const Result single = Headforge({pack_.string(), "--out", (dir_ / "single").string(), "--threads", "1"},
                                  HEADFORGE_TRAIN_BINARY);
  ASSERT_EQ(single.code, 0) << single.err;
  EXPECT_NE(FileHash(dir_ / "single" / "model.pt"), FileHash(two / "model.pt"));
}

TEST_F(DataParallel, AStopOnOneRankStopsBothAtOneStepAndThePairResumes) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  ASSERT_EQ(two_.first, 0) << Log(dir_ / "two", 0);
  const fs::path out = dir_ / "stopped";
  const int port = FreePort();
  const pid_t zero = StartRank(0, port, out), one = StartRank(1, port, out);
  // SIGTERM to rank 1 once rank 0 has saved its first checkpoint.
  int status = 0;
  const bool signalled = SignalWhen(one, SIGTERM, [&] { return fs::exists(out / "checkpoint.pt"); },
                                    std::chrono::seconds(120), &status, std::chrono::milliseconds(20));
  const int code_zero = Wait(zero);
  ASSERT_TRUE(signalled) << "rank 1 ended before the first checkpoint:\n" << Log(out, 1);
  EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 1) << Log(out, 1);
  EXPECT_EQ(code_zero, 1) << Log(out, 0);
  const std::string said = "training stopped at step ";
  const size_t at0 = Log(out, 0).find(said), at1 = Log(out, 1).find(said);
  ASSERT_NE(at0, std::string::npos) << Log(out, 0);
  ASSERT_NE(at1, std::string::npos) << Log(out, 1);
  const int step0 = std::atoi(Log(out, 0).c_str() + at0 + said.size());
  EXPECT_EQ(step0, std::atoi(Log(out, 1).c_str() + at1 + said.size()));  // both at one step
  EXPECT_LT(step0, 40);
  std::printf("rank 1 stopped by SIGTERM: both ranks stopped at step %d\n", step0);
  // One process would walk the checkpoint's pass another way: refused.
  const std::string checkpoint = FileHash(out / "checkpoint.pt");
  const Result alone = Headforge({pack_.string(), "--out", out.string(), "--threads", "1"}, HEADFORGE_TRAIN_BINARY);
  EXPECT_EQ(alone.code, 2) << alone.err;
  EXPECT_NE(alone.err.find("saved by a training of 2 views a step"), std::string::npos) << alone.err;
  EXPECT_EQ(FileHash(out / "checkpoint.pt"), checkpoint);
  // Run again, both resume from rank 0's checkpoint and end where the
  // uninterrupted pair did.
  const auto [again0, again1] = RunRanks(out);
  ASSERT_EQ(again0, 0) << Log(out, 0);
  ASSERT_EQ(again1, 0) << Log(out, 1);
  EXPECT_NE(Log(out, 1).find("resuming from the checkpoint at step " + std::to_string(step0)), std::string::npos)
      << Log(out, 1);
  EXPECT_EQ(FileHash(out / "model.pt"), FileHash(dir_ / "two" / "model.pt"));
}

// Ranks given different options are told so before the first step.
// Hosts for a test: network namespaces, each with its own address on one
// bridge (10.213.77.1, .2, ...), as machines on one network are; their
// host name is this machine's, which may resolve to its loopback (Debian
// gives it 127.0.1.1), as on many clusters' nodes. Gone with the object.
class Hosts {
 public:
  explicit Hosts(int count) {
    const std::string tag = "hft" + std::to_string(getpid() % 100000);
    bridge_ = tag + "br";
    ok_ = Ip({"link", "add", bridge_, "type", "bridge"}) && Ip({"link", "set", bridge_, "up"});
    for (int i = 0; ok_ && i < count; ++i) {
      const std::string ns = tag + "h" + std::to_string(i), outside = tag + "v" + std::to_string(i),
                        inside = tag + "p" + std::to_string(i);
      ok_ = Ip({"netns", "add", ns});
      if (!ok_) break;
      names_.push_back(ns);
      ok_ = Ip({"link", "add", outside, "type", "veth", "peer", "name", inside}) &&
            Ip({"link", "set", outside, "master", bridge_}) && Ip({"link", "set", outside, "up"}) &&
            Ip({"link", "set", inside, "netns", ns}) &&
            Ip({"-n", ns, "addr", "add", Address(i) + "/24", "dev", inside}) &&
            Ip({"-n", ns, "link", "set", inside, "up"}) && Ip({"-n", ns, "link", "set", "lo", "up"});
    }
  }
  ~Hosts() {
    for (const std::string& ns : names_) Ip({"netns", "del", ns});
    Ip({"link", "del", bridge_});
  }
  bool ok() const { return ok_; }
  const std::string& error() const { return error_; }
  const std::string& Name(int i) const { return names_[size_t(i)]; }
  static std::string Address(int i) { return "10.213.77." + std::to_string(i + 1); }

 private:
  bool Ip(const std::vector<std::string>& args) {
    const Result r = Headforge(args, "/usr/sbin/ip");
    if (r.code != 0 && error_.empty()) error_ = "ip " + args[0] + " " + args[1] + ": " + r.err;
    return r.code == 0;
  }
  std::string bridge_, error_;
  std::vector<std::string> names_;
  bool ok_ = false;
};

// Three ranks on three hosts: each finds its address on the route to rank
// 0's (its host name would give the loopback, where the others cannot reach
// it), and together they train the model one process trains with three
// views a step; the three-way sums round differently from one process's, so
// the figures agree to rounding, not to the byte.
TEST_F(DataParallel, ThreeRanksOnThreeHostsTrainTheModelOneProcessTrains) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  ASSERT_EQ(::geteuid(), 0u) << "network namespaces need root";
  Hosts hosts(3);
  ASSERT_TRUE(hosts.ok()) << hosts.error();
  const fs::path out = dir_ / "three_hosts";
  const int port = FreePort();
  pid_t pids[3];
  for (int rank = 0; rank < 3; ++rank) {
    const std::vector<std::string> args = {
        "netns", "exec", hosts.Name(rank), "env", "RANK=" + std::to_string(rank), "WORLD_SIZE=3",
        "MASTER_ADDR=" + Hosts::Address(0), "MASTER_PORT=" + std::to_string(port), HEADFORGE_TRAIN_BINARY,
        pack_.string(), "--out", out.string(), "--threads", "1", "--distributed-timeout", "60", "--set",
        "views_per_step=3"};
    const fs::path log = out.string() + ".rank" + std::to_string(rank) + ".log";
    pids[rank] = Spawn(args, log, log, "/usr/sbin/ip");
  }
  for (int rank : {2, 1, 0}) ASSERT_EQ(Wait(pids[rank]), 0) << Log(out, rank);
  EXPECT_NE(Log(out, 2).find("rank 2 of 3"), std::string::npos) << Log(out, 2);
  const Result one = Headforge({pack_.string(), "--out", (dir_ / "one_three").string(), "--threads", "1", "--set",
                                "views_per_step=3"},
                               HEADFORGE_TRAIN_BINARY);
  ASSERT_EQ(one.code, 0) << one.err;
  const std::vector<nlohmann::json> stats = StatsLines(out / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(dir_ / "one_three" / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  ASSERT_GE(stats.size(), 8u);
  for (size_t i = 0; i < stats.size(); ++i) {
    EXPECT_NEAR(stats[i]["loss"].get<double>(), expected[i]["loss"].get<double>(),
                1e-3 * expected[i]["loss"].get<double>())  // 1.4e-4 at most here
        << i;
    EXPECT_EQ(stats[i]["gaussians"], expected[i]["gaussians"]) << i;
  }
  nlohmann::json eval, expected_eval;
  ASSERT_TRUE(ReadJson(out / "eval.json", &eval).ok());
  ASSERT_TRUE(ReadJson(dir_ / "one_three" / "eval.json", &expected_eval).ok());
  EXPECT_NEAR(eval["mean"]["psnr_masked"].get<double>(), expected_eval["mean"]["psnr_masked"].get<double>(), 0.01);
}

TEST_F(DataParallel, RanksThatDoNotStartAlikeAreToldSo) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  const fs::path out = dir_ / "unalike";
  const int port = FreePort();
  const pid_t zero = StartRank(0, port, out), one = StartRank(1, port, out, {"--set", "steps=41"});
  const int code_one = Wait(one), code_zero = Wait(zero);
  for (const auto& [rank, code] : {std::pair{0, code_zero}, std::pair{1, code_one}}) {
    EXPECT_EQ(code, 2) << Log(out, rank);
    EXPECT_NE(Log(out, rank).find("the ranks do not start alike"), std::string::npos) << Log(out, rank);
  }
  EXPECT_FALSE(fs::exists(out / "model.pt"));
}

TEST_F(DataParallel, ARankThatDiesFailsTheOtherWithinItsTimeout) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  const fs::path out = dir_ / "killed";
  const int port = FreePort();
  const pid_t zero = StartRank(0, port, out), one = StartRank(1, port, out);
  int status = 0;
  ASSERT_TRUE(SignalWhen(one, SIGKILL, [&] { return fs::exists(out / "checkpoint.pt"); }, std::chrono::seconds(120),
                         &status, std::chrono::milliseconds(20)))
      << Log(out, 1);
  const auto killed = std::chrono::steady_clock::now();
  const int code = Wait(zero);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - killed).count();
  std::printf("rank 1 killed: rank 0 failed %.1f s later\n", seconds);
  EXPECT_EQ(code, 1) << Log(out, 0);
  EXPECT_LT(seconds, 60 + 15);  // --distributed-timeout 60
  EXPECT_NE(Log(out, 0).find("another rank has gone"), std::string::npos) << Log(out, 0);
}

// `headforge train` on a workspace, every rank running the command: rank 0
// runs the stage (its lock, its staging folder, the model it commits), rank
// 1 trains beside it and writes nothing; the model is the one a pack of the
// same options trains in one process with both views a step. Run again, the
// stage is up to date on rank 0, and rank 1 is told so and ends. `headforge
// run` as ranks: rank 0 runs the stages (here up to date) and trains with
// rank 1, which waited for it at train: the same model again.
TEST_F(DataParallel, HeadforgeTrainOnAWorkspaceTrainsAsRanks) {
  ASSERT_EQ(packed_.code, 0) << packed_.err;
  ASSERT_EQ(one_.code, 0) << one_.err;
  fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("data_parallel_ws"));
  const auto run = [&](const std::string& name, const std::vector<std::string>& command = {"train"}) {
    const int port = FreePort();
    pid_t pids[2];
    for (int rank = 0; rank < 2; ++rank) {
      std::vector<std::string> args = {"RANK=" + std::to_string(rank), "WORLD_SIZE=2", "MASTER_ADDR=127.0.0.1",
                                       "MASTER_PORT=" + std::to_string(port), HEADFORGE_BINARY};
      args.insert(args.end(), command.begin(), command.end());
      args.insert(args.end(), {"--workspace", ws.string(), "--train-size", "48", "--steps", "40",
                                       "--canonical-fraction", "0.5", "--triplane-resolution", "16", "--init-gaussians", "1500", "--max-gaussians",
                                       "2500", "--densify-from", "10", "--densify-every", "10", "--densify-until",
                                       "30", "--eval-every", "0", "--preview-every", "0", "--log-every", "5",
                                       "--checkpoint-every", "5", "--max-minutes", "0", "--decoder-steps", "0",
                                       "--threads", "1", "--distributed-timeout", "60"});
      const fs::path log = ws.string() + "." + name + std::to_string(rank) + ".log";
      pids[rank] = Spawn(args, log, log, "/usr/bin/env");
    }
    const int one = Wait(pids[1]), zero = Wait(pids[0]);
    return std::pair{zero, one};
  };
  const auto log = [&](const std::string& name, int rank) {
    return Slurp(ws.string() + "." + name + std::to_string(rank) + ".log");
  };
  const auto [zero, one] = run("first");
  ASSERT_EQ(zero, 0) << log("first", 0);
  ASSERT_EQ(one, 0) << log("first", 1);
  EXPECT_NE(log("first", 0).find("data-parallel over 2 ranks, 2 training views a step"), std::string::npos)
      << log("first", 0);
  EXPECT_NE(log("first", 1).find("rank 1 of 2: trained stages 1-2 beside rank 0"), std::string::npos)
      << log("first", 1);
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(dir_ / "one" / "model.pt"));
  EXPECT_NE(Headforge({"status", ws.string()}).out.find("train      done"), std::string::npos);

  const auto [again0, again1] = run("again");
  EXPECT_EQ(again0, 0) << log("again", 0);
  EXPECT_EQ(again1, 0) << log("again", 1);
  EXPECT_NE(log("again", 0).find("train: up to date"), std::string::npos) << log("again", 0);
  EXPECT_NE(log("again", 1).find("rank 0 did not train"), std::string::npos) << log("again", 1);

  ws = CopyOf(TrackedTalkingStatic(), Scratch("data_parallel_run"));
  const auto [run0, run1] = run("run", {"run", "--until", "train"});
  ASSERT_EQ(run0, 0) << log("run", 0);
  ASSERT_EQ(run1, 0) << log("run", 1);
  EXPECT_NE(log("run", 0).find("track: up to date"), std::string::npos) << log("run", 0);
  EXPECT_NE(log("run", 1).find("waiting for rank 0"), std::string::npos) << log("run", 1);
  EXPECT_NE(log("run", 1).find("rank 1 of 2: trained stages 1-2 beside rank 0"), std::string::npos) << log("run", 1);
  EXPECT_EQ(log("run", 1).find("up to date"), std::string::npos) << log("run", 1);  // the stages are rank 0's
  EXPECT_EQ(log("run", 1).find("warning"), std::string::npos) << log("run", 1);
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(dir_ / "one" / "model.pt"));
}

}  // namespace
}  // namespace headforge
