// The one training loop every trainer runs in (stages 1-2 of the
// gaussian-style avatar, its stage 3, the gan-avatar GAN and its expression
// mapping, splat-fit). The loop owns the cadence: the steps, the time limit,
// a stats.jsonl line every log_every steps with the step's figures averaged
// by name, held-out evaluations, previews and checkpoints every N steps, the
// stop on Ctrl-C or a TERM signal, and the check that training has not
// diverged. A trainer supplies its step and what it evaluates, draws and saves.
#pragma once

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/progress.h"
#include "core/stats_log.h"
#include "core/status.h"

namespace headforge {

class Checkpoint;

inline double SecondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// A training's figures since its last log line, by name: each Add() goes into
// its name's running mean (a figure a step does not give is averaged over the
// steps that gave it).
class RunningStats {
 public:
  void Add(const std::string& name, double value);
  // The means by name into `line`; then they are forgotten.
  void TakeMeans(nlohmann::json* line);
  // The first figure of the current step that was not finite (empty: none);
  // the loop clears it before each step.
  const std::string& non_finite() const { return non_finite_; }
  double non_finite_value() const { return non_finite_value_; }
  void ClearStep() { non_finite_.clear(); }
  bool empty() const { return sums_.empty(); }

  // Into a checkpoint under `prefix` and back (false: a damaged entry).
  void Save(const std::string& prefix, Checkpoint* checkpoint) const;
  bool Load(const std::string& prefix, const Checkpoint& checkpoint);

 private:
  struct Sum {
    double sum = 0;
    int64_t count = 0;
  };
  std::map<std::string, Sum> sums_;
  std::string non_finite_;
  double non_finite_value_ = 0;
};

// The processes of one data-parallel training (avatar/train/distributed.h),
// as the loop sees them: rank 0 logs, evaluates, previews and saves; every
// rank stops where any one of them stops.
class Collective {
 public:
  virtual ~Collective() = default;
  virtual int rank() const = 0;
  virtual int world() const = 0;
  // Each flag OR-ed over every rank, in place.
  virtual Status AnyOf(std::vector<uint8_t>* flags) = 0;
};

// Thrown by a trainer's step whose collective operation failed (a rank that
// has gone): the loop ends the run with its message.
struct DistributedFailure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Where a loop stands: saved in its trainer's checkpoint and read back on resume.
struct LoopState {
  int step = 0;         // steps done
  double seconds = 0;   // training time so far (all attempts)
  RunningStats stats;   // since the last log line
  size_t stats_lines = 0;  // stats.jsonl's lines at the checkpoint
  bool out_of_time = false;  // this attempt stopped at the time limit (not saved)

  void Save(Checkpoint* checkpoint) const;
  // False when the checkpoint has no loop state (another layout).
  bool Load(const Checkpoint& checkpoint);
};

struct LoopOptions {
  std::string label;               // the progress bar's and the log's: "train: gaussian-style"
  std::string what = "training";   // what an interrupt says stopped: "stage 3"
  std::string step_key = "step";   // the stats lines' step field
  nlohmann::json tags = nlohmann::json::object();  // fields of every line it writes ({"stage": 3})
  int steps = 0;
  // A checkpoint where the time limit stops training, which the trainer may
  // keep beside its model for a later attempt with a longer limit
  // (train --extend).
  bool save_at_time_limit = false;
  double max_minutes = 0;     // > 0: stop after this much training time (all attempts)
  double clock_offset = 0;    // seconds added to the lines' "seconds" (an earlier loop's time)
  int log_every = 100;
  int eval_every = 0;         // 0: none inside the loop
  int preview_every = 0;      // 0: none
  int checkpoint_every = 0;   // 0: no checkpoint (an interrupt loses the loop's progress)
  // Several processes training one model: rank 0 alone writes (log lines,
  // evaluations, previews, checkpoints); a stop, a time limit or the
  // trainer's Done() on any rank ends the step on every rank. Null: one process.
  Collective* collective = nullptr;
  // What an interrupt's message tells the user to do.
  std::string resume_hint = "the checkpoint is saved: run the same command again to resume";
};

// What a trainer gives the loop.
class LoopTrainer {
 public:
  virtual ~LoopTrainer() = default;
  // Step `step` (1-based); its figures by name into `stats`. A figure that is
  // not finite ends training as diverged.
  virtual void Step(int step, RunningStats* stats) = 0;
  // What the user can change when training diverges.
  virtual std::string DivergenceAdvice() const = 0;
  // Fields of the log line at `step` besides the means (phase, Gaussians).
  virtual void Describe(int step, nlohmann::json* line) {}
  // A step after which a log line and a preview are due whatever the
  // cadence (the end of a phase).
  virtual bool Boundary(int step) const { return false; }
  // The held-out figures at `step` into `line`; false: this trainer has none.
  virtual bool Evaluate(int step, nlohmann::json* line) { return false; }
  virtual Status Preview(int step) { return Status::Ok(); }
  // The checkpoint with `state` in it.
  virtual Status Save(const LoopState& state) { return Status::Ok(); }
  // A warning the last step raised (a collapsing GAN), or empty.
  virtual std::string TakeWarning() { return {}; }
  // True when training should end after `step`, saying why (asked after
  // each step but the last, after its evaluation when it has one: a
  // validation score that stopped rising).
  virtual bool Done(int step, std::string* why) { return false; }
};

// Runs `trainer` from state->step + 1 to options.steps (or the time limit):
// after it, state->step is the last step done and state->seconds the
// training time. Interrupted after saving where an interrupt came; Internal
// where a figure diverged.
Status RunLoop(const LoopOptions& options, LoopTrainer* trainer, LoopState* state, StatsLog* stats,
               Progress* progress);

// `out_dir`'s stats.jsonl for a training run: lines from an attempt that
// left no checkpoint (checkpoint.pt, decoder_checkpoint.pt) are dropped; a
// resumed run truncates it to its checkpoint's line count itself.
Status OpenTrainStats(const fs::path& out_dir, StatsLog* stats);

}  // namespace headforge
