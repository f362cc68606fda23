// Running another program (COLMAP, ffmpeg) without a shell.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// Runs `args` (args[0] looked up on PATH) with `env` added to the
// environment, stdout and stderr appended to `log`, and waits for it. Ok with
// its exit code in *exit_code (-1 when a signal ended it); NotFound when the
// program could not be started. The program is killed when the calling
// process dies, even by SIGKILL.
Status RunProgram(const std::vector<std::string>& args, const fs::path& log, int* exit_code,
                  const std::vector<std::pair<std::string, std::string>>& env = {});

}  // namespace headforge
