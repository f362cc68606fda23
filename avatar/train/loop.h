// Pieces every training loop shares: its clock, and the end of a step that
// writes the checkpoint and stops on an interrupt.
#pragma once

#include <chrono>
#include <functional>
#include <string>

#include "core/progress.h"
#include "core/status.h"

namespace headforge {

inline double SecondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// After step `step` of `steps`: on an interrupt (Ctrl-C, a TERM signal) or
// every `every` steps, `save` writes the checkpoint (never after the last
// step); an interrupt then ends the loop with Interrupted, naming `what`
// stopped where and how to resume.
Status CheckpointOrStop(const std::string& what, int step, int steps, bool last, int every,
                        const std::function<Status()>& save, Progress* progress);

}  // namespace headforge
