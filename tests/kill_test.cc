// kill -9 anywhere: `headforge run` killed without warning at a random moment
// inside calibrate, align and track of a GRID clip, and inside calibrate
// while COLMAP runs on a simulated orbit; each time run again. The run
// completes, the deterministic stages' outputs are byte-identical to an
// uninterrupted run's, and no COLMAP outlives the run that started it.
// (Ingest, train and export have their own kill tests: cli_test, train_test,
// gan_avatar_test.) The random moments come from a seed the test prints;
// HEADFORGE_KILL_SEED repeats one.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <thread>

#include "core/fs.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

const fs::path kGrid = fs::path(HEADFORGE_TEST_SHARED_DATA) / "video" / "grid";

unsigned Seed() {
  const char* given = std::getenv("HEADFORGE_KILL_SEED");
  const unsigned seed = given ? static_cast<unsigned>(std::strtoul(given, nullptr, 10)) : std::random_device{}();
  std::printf("kill moments from seed %u (HEADFORGE_KILL_SEED=%u repeats them)\n", seed, seed);
  return seed;
}

// The pids of `parent`'s children whose command is `name`.
std::vector<pid_t> ChildrenNamed(pid_t parent, const std::string& name) {
  std::vector<pid_t> found;
  std::error_code ec;
  for (auto it = fs::directory_iterator("/proc", ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string text = Slurp(it->path() / "stat");  // "pid (comm) state ppid ..."
    const size_t open = text.find('('), close = text.rfind(')');
    if (open == std::string::npos || close == std::string::npos) continue;
    int ppid = 0;
    char state = 0;
    if (std::sscanf(text.c_str() + close + 1, " %c %d", &state, &ppid) != 2) continue;
    if (ppid == parent && state != 'Z' && text.substr(open + 1, close - open - 1) == name)
      found.push_back(std::atoi(text.c_str()));
  }
  return found;
}

// True when `pid` has ended (gone, or a zombie).
bool Ended(pid_t pid) {
  const std::string text = Slurp("/proc/" + std::to_string(pid) + "/stat");
  const size_t close = text.rfind(')');
  return close == std::string::npos || (close + 2 < text.size() && text[close + 2] == 'Z');
}

// Starts `args`, and once `stage`'s staging folder exists waits `delay` (or
// until the folder goes, the stage ended) and kills the run (SIGKILL). False
// when the run ended first.
bool KillInside(const std::vector<std::string>& args, const fs::path& ws, const std::string& stage,
                std::chrono::milliseconds delay, const fs::path& log) {
  const pid_t pid = Spawn(args, log, log);
  const fs::path staging = ws / ".staging" / stage;
  std::chrono::steady_clock::time_point seen{};
  int status = 0;
  const bool killed = SignalWhen(pid, SIGKILL, [&] {
    if (seen == std::chrono::steady_clock::time_point{}) {
      if (!fs::exists(staging)) return false;
      seen = std::chrono::steady_clock::now();
    }
    // Past the moment, or the stage ended sooner than it did before: now.
    return std::chrono::steady_clock::now() - seen >= delay || !fs::exists(staging);
  }, std::chrono::seconds(600), &status, std::chrono::milliseconds(1));
  if (killed) {
    EXPECT_TRUE(WIFSIGNALED(status));
  }
  return killed;
}

TEST(KillAnywhere, EveryStageOfAGridRunResumesToTheSameOutputs) {
  const std::vector<std::string> run = {"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--until", "track"};
  // The same run, never interrupted (shared with cli_test and track_test).
  const fs::path reference = SharedRun("grid_bbaf2n", {(kGrid / "bbaf2n.mpg").string()});
  ASSERT_TRUE(fs::exists(reference / ".complete"));
  const fs::path ws = fs::temp_directory_path() / "hf_kill_anywhere_grid";
  fs::remove_all(ws);
  std::vector<std::string> args = run;
  args.insert(args.end(), {"--workspace", ws.string()});

  // The random moment lies within the first 80% of the stage's wall time in
  // the uninterrupted run (workspace.json records it), so that it falls inside.
  nlohmann::json manifest;
  ASSERT_TRUE(ReadJson(reference / "workspace.json", &manifest).ok());
  auto wall_ms = [&](const std::string& stage) {
    for (const auto& s : manifest["stages"])
      if (s["name"] == stage) return static_cast<int>(s["wall_time_s"].get<double>() * 800.0);
    ADD_FAILURE() << stage << " not in the reference's workspace.json";
    return 0;
  };
  std::mt19937 rng(Seed());
  for (const char* stage : {"calibrate", "align", "track"}) {
    nlohmann::json now;  // a kill that came as a stage ended may have left the next one done too
    if (ReadJson(ws / "workspace.json", &now).ok()) {
      bool done = false;
      for (const auto& s : now["stages"]) done = done || (s["name"] == stage && s["status"] == "done");
      if (done) {
        std::printf("%s was done before its kill\n", stage);
        continue;
      }
    }
    const auto delay = std::chrono::milliseconds(std::uniform_int_distribution<int>(0, wall_ms(stage))(rng));
    const fs::path log = ws.string() + "_" + stage + ".log";
    ASSERT_TRUE(KillInside(args, ws, stage, delay, log))
        << "the run ended before it was killed in " << stage << ":\n" << Slurp(log);
    std::printf("killed %lld ms into %s\n", static_cast<long long>(delay.count()), stage);
    // Interrupted, unless the kill came between one stage's end and the next's start.
    const Result status = Headforge({"status", ws.string()});
    nlohmann::json after;
    ASSERT_TRUE(ReadJson(ws / "workspace.json", &after).ok());
    bool done = false;
    for (const auto& s : after["stages"]) done = done || (s["name"] == stage && s["status"] == "done");
    EXPECT_TRUE(done || status.out.find("interrupted") != std::string::npos) << stage << "\n" << status.out;
  }
  const Result last = Headforge(args);
  ASSERT_EQ(last.code, 0) << last.err;
  for (const char* file : {"capture.json", "landmarks.json", "cameras.json", "alignment.json", "cameras_head.json"})
    EXPECT_EQ(FileHash(ws / file), FileHash(reference / file)) << file << " differs from the uninterrupted run's";
  // tracking.json also records how long the fit took: everything else is equal.
  nlohmann::json tracked, tracked_reference;
  ASSERT_TRUE(ReadJson(ws / "tracking.json", &tracked).ok());
  ASSERT_TRUE(ReadJson(reference / "tracking.json", &tracked_reference).ok());
  ASSERT_TRUE(tracked.contains("seconds"));
  tracked.erase("seconds");
  tracked_reference.erase("seconds");
  EXPECT_TRUE(tracked == tracked_reference) << "tracking.json differs from the uninterrupted run's";
  EXPECT_FALSE(fs::exists(ws / ".staging" / "calibrate"));
  EXPECT_FALSE(fs::exists(ws / ".staging" / "track"));
  // Nothing is left to redo.
  const Result again = Headforge(args);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_NE(again.err.find("up to date"), std::string::npos) << again.err;
}


TEST(KillAnywhere, CalibrateKilledWhileColmapRunsLeavesNoColmapBehindAndResumes) {
  const fs::path root = fs::temp_directory_path() / "hf_kill_anywhere_colmap";
  fs::remove_all(root);
  fs::create_directories(root);
  // The first 16 frames of the tests' small orbit (scenes/small_orbit.toml).
  const Result simulated =
      Headforge({"simulate", "--scene", (fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes" / "small_orbit.toml").string(),
                 "--frames", "16", "--out", (root / "sim").string()});
  ASSERT_EQ(simulated.code, 0) << simulated.err;
  const fs::path ws = root / "ws";
  const std::vector<std::string> inputs = SimulatedInputs(root / "sim");
  ASSERT_EQ(inputs.size(), 1u);
  const std::vector<std::string> args = {"run", "--video", inputs[0], "--until", "calibrate", "--calibrate.mode",
                                         "colmap", "--workspace", ws.string()};
  std::mt19937 rng(Seed());
  // Killed while COLMAP runs: at a random moment in the first second after its
  // first program starts.
  const auto delay = std::chrono::milliseconds(std::uniform_int_distribution<int>(0, 1000)(rng));
  const fs::path log = root / "killed.log";
  const pid_t pid = Spawn(args, log, log);
  std::chrono::steady_clock::time_point seen{};
  std::vector<pid_t> colmap;
  int status = 0;
  const bool killed = SignalWhen(pid, SIGKILL, [&] {
    const std::vector<pid_t> now = ChildrenNamed(pid, "colmap");
    if (now.empty()) return false;
    colmap = now;
    if (seen == std::chrono::steady_clock::time_point{}) seen = std::chrono::steady_clock::now();
    return std::chrono::steady_clock::now() - seen >= delay;
  }, std::chrono::seconds(600), &status, std::chrono::milliseconds(10));
  ASSERT_TRUE(killed) << "the run ended before COLMAP ran long enough to be interrupted:\n" << Slurp(log);
  ASSERT_FALSE(colmap.empty());
  std::printf("killed %lld ms after COLMAP started (pid %d)\n", static_cast<long long>(delay.count()), colmap[0]);
  // COLMAP dies with the run: a leftover would go on writing into the
  // staging folder the next run starts from.
  bool ended = false;
  for (int i = 0; i < 300 && !ended; ++i) {
    ended = Ended(colmap[0]);
    if (!ended) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(ended) << "COLMAP outlived the run that started it";
  if (!ended) kill(colmap[0], SIGKILL);

  const Result resumed = Headforge(args);
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_NE(resumed.err.find("interrupted"), std::string::npos) << resumed.err;
  nlohmann::json cameras;
  ASSERT_TRUE(ReadJson(ws / "cameras.json", &cameras).ok());
  EXPECT_EQ(cameras["total"], 16);
  // The resumed run registers the orbit as one run from nothing does: all 16
  // frames alone; COLMAP's mapper, multi-threaded, registered 14 once when the
  // suite loaded both cores (the same kill moments passed alone twice).
  EXPECT_GE(cameras["registered"].get<int>(), 14) << "the orbit registered";
  EXPECT_FALSE(fs::exists(ws / ".staging" / "calibrate"));
}

}  // namespace
}  // namespace headforge
