#include "core/process.h"

#include <fcntl.h>
#include <spawn.h>
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
  for (char** e = environ; *e != nullptr; ++e) environment.emplace_back(*e);
  for (const auto& [name, value] : env) environment.push_back(name + "=" + value);
  std::vector<char*> argv, envp;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  for (const std::string& e : environment) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  pid_t pid = -1;
  const int started = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  if (started != 0) return Status::NotFound("cannot run " + args[0] + ": " + std::strerror(started));
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return Status::Internal("waiting for " + args[0] + " failed");
  *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (*exit_code == 127) return Status::NotFound("cannot run " + args[0] + " (not installed, or not on PATH)");
  return Status::Ok();
}

}  // namespace headforge
