// Runs the real `headforge` binary from an integration test.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/fs.h"

extern char** environ;

namespace headforge {

struct Result {
  int code = -1;
  std::string out, err;
};

// `binary` (headforge unless named) with `args`, its output into `out` and `err`.
inline pid_t Spawn(const std::vector<std::string>& args, const fs::path& out, const fs::path& err,
                   const char* binary = HEADFORGE_BINARY) {
  std::vector<std::string> full = {binary};
  full.insert(full.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : full) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  EXPECT_EQ(posix_spawn(&pid, binary, &actions, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&actions);
  return pid;
}

inline std::string Slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Entries in `dir` (0 when it does not exist).
inline size_t CountFiles(const fs::path& dir) {
  std::error_code ec;
  size_t n = 0;
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) ++n;
  return n;
}

inline Result Headforge(const std::vector<std::string>& args, const char* binary = HEADFORGE_BINARY) {
  const fs::path out = fs::temp_directory_path() / ("hf_cli_out_" + std::to_string(getpid()));
  const fs::path err = fs::temp_directory_path() / ("hf_cli_err_" + std::to_string(getpid()));
  const pid_t pid = Spawn(args, out, err, binary);
  int status = 0;
  waitpid(pid, &status, 0);
  Result r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = Slurp(out);
  r.err = Slurp(err);
  return r;
}

// The lines of a run's stderr that give a reason ("headforge: ..."), not
// progress or log lines.
inline std::vector<std::string> ReasonLines(const std::string& err) {
  std::vector<std::string> lines;
  std::istringstream in(err);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("headforge: ", 0) == 0) lines.push_back(line);
  return lines;
}

// headforge with `args` under a file-size limit of `kib` KiB (ulimit -f):
// what a full disk does to the file being written.
inline Result HeadforgeWithFileLimit(const std::vector<std::string>& args, int kib) {
  std::vector<std::string> shell = {"-c", "ulimit -f " + std::to_string(kib) + " && exec \"$0\" \"$@\"",
                                    HEADFORGE_BINARY};
  shell.insert(shell.end(), args.begin(), args.end());
  return Headforge(shell, "/bin/sh");
}

// Polls every `poll` until `ready()` holds (or `timeout` passes), then sends
// `signal` to `pid` and waits for it to end. False when the process ended by
// itself first. *status is its wait status either way.
inline bool SignalWhen(pid_t pid, int signal, const std::function<bool()>& ready, std::chrono::seconds timeout,
                       int* status, std::chrono::milliseconds poll = std::chrono::milliseconds(2)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (waitpid(pid, status, WNOHANG) == pid) return false;
    if (ready()) break;
    std::this_thread::sleep_for(poll);
  }
  EXPECT_EQ(kill(pid, signal), 0);
  waitpid(pid, status, 0);
  return true;
}

// The number of lines of a text file (0 when it does not exist).
inline size_t CountLines(const fs::path& path) {
  const std::string text = Slurp(path);
  return size_t(std::count(text.begin(), text.end(), '\n'));
}

// Starts a training run (`args`, its output into `log`) and kills it with
// SIGKILL once its staged model folder `staging` holds `checkpoint` and
// `stats_lines` lines of stats.jsonl; a failure, with the log, when the run
// ended by itself first.
inline ::testing::AssertionResult KillTrainingMidway(const std::vector<std::string>& args, const fs::path& staging,
                                                     size_t stats_lines, const fs::path& log,
                                                     const std::string& checkpoint = "checkpoint.pt") {
  const pid_t pid = Spawn(args, log, log);
  int status = 0;
  const bool killed = SignalWhen(pid, SIGKILL, [&] {
    return fs::exists(staging / checkpoint) && CountLines(staging / "stats.jsonl") >= stats_lines;
  }, std::chrono::seconds(300), &status);
  if (!killed) return ::testing::AssertionFailure() << "training finished before it could be killed:\n" << Slurp(log);
  if (!WIFSIGNALED(status)) return ::testing::AssertionFailure() << "the run ended otherwise:\n" << Slurp(log);
  return ::testing::AssertionSuccess();
}

}  // namespace headforge
