// Pieces every training loop shares: its clock, the end of a step that
// writes the checkpoint and stops on an interrupt, and its stats.jsonl.
#pragma once

#include <chrono>
#include <functional>
#include <string>

#include "core/fs.h"
#include "core/progress.h"
#include "core/stats_log.h"
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

// `out_dir`'s stats.jsonl for a training run: lines from an attempt that
// left no checkpoint (checkpoint.pt, decoder_checkpoint.pt) are dropped; a
// resumed run truncates it to its checkpoint's line count itself.
Status OpenTrainStats(const fs::path& out_dir, StatsLog* stats);

}  // namespace headforge
