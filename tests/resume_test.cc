// Long stages survive interruptions: `headforge splat-fit` (the pattern the
// train stage follows) stopped by SIGTERM, then killed outright, and run
// again each time, ends with exactly the files of a fit that was never
// interrupted.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <thread>

#include "core/fs.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

const fs::path kScene = fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes" / "orbit_360.toml";

std::vector<std::string> FitArgs(const fs::path& out) {
  return {"splat-fit", "--scene", kScene.string(), "--out", out.string(), "--resolution", "48", "--frames", "24",
          "--iterations", "100", "--init-points", "3000", "--eval-every", "0", "--densify-until", "60",
          "--checkpoint-every", "10", "--log-every", "10", "--max-minutes", "0", "--threads", "2"};
}

// Starts a fit and sends `signal` once its checkpoint has reached at least
// `step`; returns the exit status.
int InterruptAt(const std::vector<std::string>& args, const fs::path& out, int step, int signal) {
  const fs::path log = out.string() + ".log";
  const pid_t pid = Spawn(args, log, log);
  const fs::path checkpoint = out / ".staging" / "splat_fit" / "checkpoint.pt";
  const fs::path stats = out / ".staging" / "splat_fit" / "stats.jsonl";
  int status = 0;
  // stats.jsonl gets a line every 10 steps (log_every): count them.
  const bool signalled = SignalWhen(pid, signal, [&] {
    return fs::exists(checkpoint) && int(CountLines(stats)) * 10 >= step;
  }, std::chrono::seconds(300), &status, std::chrono::milliseconds(20));
  if (!signalled) ADD_FAILURE() << "the fit ended before it was interrupted:\n" << Slurp(log);
  return status;
}

TEST(Resume, InterruptedSplatFitContinuesFromItsCheckpoint) {
  const fs::path root = fs::temp_directory_path() / "hf_resume_test";
  fs::remove_all(root);
  fs::create_directories(root);
  const fs::path reference = root / "reference", cut = root / "cut";
  const Result whole = Headforge(FitArgs(reference));
  ASSERT_EQ(whole.code, 0) << whole.err;

  // SIGTERM: the fit saves a checkpoint, says how to resume, and exits 1.
  const int stopped = InterruptAt(FitArgs(cut), cut, 30, SIGTERM);
  ASSERT_TRUE(WIFEXITED(stopped)) << "SIGTERM should be caught";
  EXPECT_EQ(WEXITSTATUS(stopped), 1);
  const std::string said = Slurp(cut.string() + ".log");
  EXPECT_NE(said.find("run the same command again to resume"), std::string::npos) << said;
  nlohmann::json manifest;
  ASSERT_TRUE(ReadJson(cut / "workspace.json", &manifest).ok());
  EXPECT_EQ(manifest["stages"][0]["status"], "interrupted");
  const Result status = Headforge({"status", cut.string()});
  EXPECT_NE(status.out.find("interrupted"), std::string::npos) << status.out;

  // Resumed, then killed outright past a later checkpoint.
  const int killed = InterruptAt(FitArgs(cut), cut, 70, SIGKILL);
  ASSERT_TRUE(WIFSIGNALED(killed));
  const std::string resumed_log = Slurp(cut.string() + ".log");
  EXPECT_NE(resumed_log.find("resuming from the checkpoint at step"), std::string::npos) << resumed_log;

  // The last run finishes from the last checkpoint before the kill (one every
  // 10 steps; the kill came at step 70 or a little later), not from step 0
  // or from where SIGTERM stopped the first run (about step 30).
  const Result last = Headforge(FitArgs(cut));
  ASSERT_EQ(last.code, 0) << last.err;
  nlohmann::json report;
  ASSERT_TRUE(ReadJson(cut / "report.json", &report).ok());
  EXPECT_EQ(report["steps"], 100);
  EXPECT_GE(report["resumed_from"].get<int>(), 60);
  EXPECT_LT(report["resumed_from"].get<int>(), 100);
  std::printf("splat-fit resumed from step %d after SIGTERM and SIGKILL\n", report["resumed_from"].get<int>());
  // The same Gaussians, bit for bit, as the fit that never stopped.
  EXPECT_EQ(FileHash(cut / "gaussians.ply"), FileHash(reference / "gaussians.ply"));
  nlohmann::json reference_report;
  ASSERT_TRUE(ReadJson(reference / "report.json", &reference_report).ok());
  EXPECT_EQ(report["test_psnr"], reference_report["test_psnr"]);
  EXPECT_EQ(report["gaussians"], reference_report["gaussians"]);
  // A fourth run finds it up to date.
  const Result again = Headforge(FitArgs(cut));
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_NE(again.err.find("up to date"), std::string::npos) << again.err;
  EXPECT_FALSE(fs::exists(cut / ".staging" / "splat_fit"));
}

}  // namespace
}  // namespace headforge
