// RunProgram: exit codes, the log, the environment, a program that does not
// exist, and a program that does not outlive the process that ran it.
#include "core/process.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>

namespace headforge {
namespace {

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_process_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string Read(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(RunProgram, ExitCodeAndBothOutputsInTheLog) {
  const fs::path log = Scratch("exit") / "log.txt";
  int code = -2;
  ASSERT_TRUE(RunProgram({"sh", "-c", "echo to-out; echo to-err >&2; exit 3"}, log, &code).ok());
  EXPECT_EQ(code, 3);
  EXPECT_NE(Read(log).find("to-out"), std::string::npos);
  EXPECT_NE(Read(log).find("to-err"), std::string::npos);
}

TEST(RunProgram, AddedVariablesReplaceTheInheritedOnes) {
  const fs::path log = Scratch("env") / "log.txt";
  ::setenv("HF_PROCESS_TEST", "inherited", 1);
  int code = -2;
  ASSERT_TRUE(RunProgram({"sh", "-c", "echo value=$HF_PROCESS_TEST"}, log, &code, {{"HF_PROCESS_TEST", "given"}}).ok());
  EXPECT_EQ(code, 0);
  EXPECT_NE(Read(log).find("value=given"), std::string::npos) << Read(log);
  ::unsetenv("HF_PROCESS_TEST");
}

TEST(RunProgram, AMissingProgramIsNotFoundByName) {
  const fs::path log = Scratch("missing") / "log.txt";
  int code = -2;
  const Status status = RunProgram({"hf-no-such-program"}, log, &code);
  ASSERT_EQ(status.code(), Status::Code::kNotFound);
  EXPECT_NE(status.message().find("hf-no-such-program"), std::string::npos);
}

// A caller whose stdin and stdout are closed: the log and /dev/null take fds 0
// and 1, and the program still writes to the log.
TEST(RunProgram, ACallerWithClosedStreamsStillGetsTheOutput) {
  const fs::path log = Scratch("closed") / "log.txt";
  const pid_t caller = ::fork();
  ASSERT_GE(caller, 0);
  if (caller == 0) {
    ::close(0);
    ::close(1);
    int code = -2;
    const bool ran = RunProgram({"sh", "-c", "echo to-out"}, log, &code).ok();
    ::_exit(ran && code == 0 ? 0 : 1);
  }
  int status = 0;
  ::waitpid(caller, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the program failed with its output closed";
  EXPECT_NE(Read(log).find("to-out"), std::string::npos) << Read(log);
}

// True when `pid` has ended (gone, or a zombie nobody has reaped yet).
bool Ended(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(stat, text)) return true;
  const size_t close = text.rfind(')');
  return close != std::string::npos && close + 2 < text.size() && text[close + 2] == 'Z';
}

TEST(RunProgram, TheProgramDiesWithTheProcessThatRanIt) {
  const fs::path dir = Scratch("orphan");
  const fs::path pid_file = dir / "pid";
  const pid_t runner = ::fork();
  ASSERT_GE(runner, 0);
  if (runner == 0) {
    int code = 0;
    // The shell writes its pid and becomes `sleep` (same pid).
    RunProgram({"sh", "-c", "echo $$ > " + pid_file.string() + ".tmp && mv " + pid_file.string() + ".tmp " +
                                pid_file.string() + " && exec sleep 60"},
               dir / "log.txt", &code);
    ::_exit(0);
  }
  pid_t program = 0;
  for (int i = 0; i < 500 && program == 0; ++i) {
    std::ifstream in(pid_file);
    if (!(in >> program)) program = 0;
    if (program == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GT(program, 0) << "the program did not start";
  EXPECT_FALSE(Ended(program));
  ::kill(runner, SIGKILL);  // as kill -9 would
  ::waitpid(runner, nullptr, 0);
  bool ended = false;
  for (int i = 0; i < 200 && !ended; ++i) {
    ended = Ended(program);
    if (!ended) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(ended) << "the program outlived the process that ran it";
  if (!ended) ::kill(program, SIGKILL);
}

}  // namespace
}  // namespace headforge
