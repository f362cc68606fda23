#include "core/process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

extern char** environ;

namespace headforge {

Status RunProgram(const std::vector<std::string>& args, const fs::path& log, int* exit_code,
                  const std::vector<std::pair<std::string, std::string>>& env) {
  if (args.empty()) return Status::InvalidArgument("RunProgram: no program");
  std::vector<std::string> environment;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry = *e;
    bool replaced = false;  // by `env`: the first of two entries of a name is the one read
    for (const auto& [name, value] : env) replaced = replaced || entry.rfind(name + "=", 0) == 0;
    if (!replaced) environment.push_back(entry);
  }
  for (const auto& [name, value] : env) environment.push_back(name + "=" + value);
  std::vector<char*> argv, envp;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  for (const std::string& e : environment) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  // Everything the child needs is made before fork: between fork and exec it
  // calls only async-signal-safe functions.
  // Above 2, so that the child's dup2 onto 0, 1 and 2 never meets them (a
  // caller with a closed stdin or stdout would have them handed out there).
  auto above_stdio = [](int fd) {
    if (fd < 0 || fd > 2) return fd;
    const int moved = ::fcntl(fd, F_DUPFD_CLOEXEC, 3);
    ::close(fd);
    return moved;
  };
  const int log_fd = above_stdio(::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644));
  if (log_fd < 0) return Status::IoError("cannot write " + log.string() + ": " + std::strerror(errno));
  const int null_fd = above_stdio(::open("/dev/null", O_RDONLY | O_CLOEXEC));
  int exec_error[2];  // the child writes exec's errno here when exec fails
  if (null_fd < 0 || ::pipe2(exec_error, O_CLOEXEC) != 0) {
    ::close(log_fd);
    if (null_fd >= 0) ::close(null_fd);
    return Status::Internal("cannot start " + args[0] + ": " + std::strerror(errno));
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    // The program dies with HeadForge: a run killed outright (kill -9) leaves
    // no COLMAP behind writing into the staging folder the next run resumes.
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(null_fd, 0);
    ::dup2(log_fd, 1);
    ::dup2(log_fd, 2);
    ::execvpe(argv[0], argv.data(), envp.data());
    const int e = errno;
    [[maybe_unused]] const ssize_t n = ::write(exec_error[1], &e, sizeof(e));
    ::_exit(127);
  }
  const int fork_errno = errno;
  ::close(log_fd);
  ::close(null_fd);
  ::close(exec_error[1]);
  if (pid < 0) {
    ::close(exec_error[0]);
    return Status::Internal("cannot start " + args[0] + ": " + std::strerror(fork_errno));
  }
  int started = 0;
  ssize_t got;
  while ((got = ::read(exec_error[0], &started, sizeof(started))) < 0 && errno == EINTR) {
  }
  ::close(exec_error[0]);
  if (got == static_cast<ssize_t>(sizeof(started))) {
    while (waitpid(pid, nullptr, 0) < 0 && errno == EINTR) {
    }
    return Status::NotFound("cannot run " + args[0] + ": " + std::strerror(started));
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return Status::Internal("waiting for " + args[0] + " failed");
  *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (*exit_code == 127) return Status::NotFound("cannot run " + args[0] + " (not installed, or not on PATH)");
  return Status::Ok();
}

}  // namespace headforge
