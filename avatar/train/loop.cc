#include "avatar/train/loop.h"

#include <cmath>
#include <cstdio>

#include "avatar/train/checkpoint.h"
#include "core/interrupt.h"
#include "core/log.h"

namespace headforge {

void RunningStats::Add(const std::string& name, double value) {
  if (!std::isfinite(value) && non_finite_.empty()) {
    non_finite_ = name;
    non_finite_value_ = value;
  }
  Sum& s = sums_[name];
  s.sum += value;
  ++s.count;
}

void RunningStats::TakeMeans(nlohmann::json* line) {
  for (const auto& [name, s] : sums_) (*line)[name] = s.sum / double(std::max<int64_t>(s.count, 1));
  sums_.clear();
}

void RunningStats::Save(const std::string& prefix, Checkpoint* checkpoint) const {
  checkpoint->Put(prefix + "count", int64_t(sums_.size()));
  int64_t k = 0;
  for (const auto& [name, s] : sums_) {
    const std::string key = prefix + std::to_string(k++) + ".";
    checkpoint->PutText(key + "name", name);
    checkpoint->Put(key + "sum", s.sum);
    checkpoint->Put(key + "count", s.count);
  }
}

bool RunningStats::Load(const std::string& prefix, const Checkpoint& checkpoint) {
  sums_.clear();
  int64_t count = 0;
  if (!checkpoint.Get(prefix + "count", &count)) return false;
  for (int64_t k = 0; k < count; ++k) {
    const std::string key = prefix + std::to_string(k) + ".";
    std::string name;
    Sum s;
    if (!checkpoint.GetText(key + "name", &name) || !checkpoint.Get(key + "sum", &s.sum) ||
        !checkpoint.Get(key + "count", &s.count))
      return false;
    sums_[name] = s;
  }
  return true;
}

void LoopState::Save(Checkpoint* checkpoint) const {
  checkpoint->Put("loop.step", int64_t(step));
  checkpoint->Put("loop.seconds", seconds);
  checkpoint->Put("loop.stats_lines", int64_t(stats_lines));
  stats.Save("loop.stats.", checkpoint);
}

bool LoopState::Load(const Checkpoint& checkpoint) {
  int64_t s = 0, lines = 0;
  if (!checkpoint.Get("loop.step", &s) || !checkpoint.Get("loop.seconds", &seconds) ||
      !checkpoint.Get("loop.stats_lines", &lines) || !stats.Load("loop.stats.", checkpoint))
    return false;
  step = int(s);
  stats_lines = size_t(lines);
  return true;
}

namespace {

std::string Number(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", value);
  return text;
}

}  // namespace

Status RunLoop(const LoopOptions& options, LoopTrainer* trainer, LoopState* state, StatsLog* stats,
               Progress* progress) {
  const auto start = std::chrono::steady_clock::now();
  const double before = state->seconds;
  Collective* const group = options.collective;
  const bool writes = group == nullptr || group->rank() == 0;
  auto elapsed = [&] { return before + SecondsSince(start); };
  auto line_for = [&](int step) {
    nlohmann::json line = options.tags;
    line[options.step_key] = step;
    return line;
  };
  // The figures since the last log line, averaged, with the trainer's own fields.
  auto log_line = [&](int step) {
    nlohmann::json line = line_for(step);
    state->stats.TakeMeans(&line);
    trainer->Describe(step, &line);
    line["seconds"] = options.clock_offset + elapsed();
    if (writes) stats->Append(line.dump());
  };
  // A checkpoint of where the loop stands now.
  auto save = [&] {
    if (!writes) return Status::Ok();
    LoopState now = *state;
    now.seconds = elapsed();
    now.stats_lines = stats->size();
    return trainer->Save(now);
  };
  std::string label = options.label;
  if (options.max_minutes > 0)
    label += " (" + std::to_string(options.steps) + " steps or " + Number(options.max_minutes) +
             " min, whichever comes first)";
  progress->Start(label, options.steps);
  progress->Resume(state->step);
  if (options.max_minutes > 0) progress->LimitTime(60.0 * options.max_minutes - before);
  for (int step = state->step + 1; step <= options.steps; ++step) {
    state->stats.ClearStep();
    try {
      trainer->Step(step, &state->stats);
    } catch (const DistributedFailure& e) {
      progress->Finish("failed");
      state->seconds = elapsed();
      return Status::IoError(options.label + ": step " + std::to_string(step) + ": " + e.what());
    }
    if (!state->stats.non_finite().empty()) {
      progress->Finish("diverged");
      state->seconds = elapsed();
      return Status::Internal(options.label + ": " + state->stats.non_finite() + " became " +
                              Number(state->stats.non_finite_value()) + " at step " + std::to_string(step) + "; " +
                              trainer->DivergenceAdvice() + " (a changed option starts training over)");
    }
    if (const std::string warning = trainer->TakeWarning(); !warning.empty()) {
      HF_LOG(Warning) << options.label << ": step " << step << ": " << warning;
      nlohmann::json line = line_for(step);
      line["warning"] = warning;
      if (writes) stats->Append(line.dump());
    }
    state->step = step;
    progress->Advance();
    bool out_of_time = options.max_minutes > 0 && elapsed() > 60.0 * options.max_minutes;
    bool stop = InterruptRequested();
    if (group) {
      // One rank's time limit or stop is every rank's (rank 0's clock may
      // cross the limit a step before another's).
      std::vector<uint8_t> flags = {uint8_t(out_of_time), uint8_t(stop)};
      if (Status s = group->AnyOf(&flags); !s.ok()) {
        progress->Finish("failed");
        state->seconds = elapsed();
        return Status::IoError(options.label + ": step " + std::to_string(step) + ": " + s.message());
      }
      out_of_time = flags[0] != 0;
      stop = flags[1] != 0;
    }
    const bool last = step == options.steps || out_of_time;
    const bool boundary = trainer->Boundary(step);
    if (step % std::max(options.log_every, 1) == 0 || last || boundary) log_line(step);
    if (writes && !last && options.eval_every > 0 && step % options.eval_every == 0) {
      nlohmann::json line = line_for(step);
      if (trainer->Evaluate(step, &line)) {
        line["seconds"] = options.clock_offset + elapsed();
        stats->Append(line.dump());
      }
    }
    if (writes && (boundary || (options.preview_every > 0 && step % options.preview_every == 0)))
      HF_RETURN_IF_ERROR(trainer->Preview(step));
    std::string why;
    bool done = !last && writes && trainer->Done(step, &why);
    if (group && !last) {
      // Done() follows rank 0's evaluations: its answer goes to every rank.
      std::vector<uint8_t> flags = {uint8_t(done)};
      if (Status s = group->AnyOf(&flags); !s.ok()) {
        progress->Finish("failed");
        state->seconds = elapsed();
        return Status::IoError(options.label + ": step " + std::to_string(step) + ": " + s.message());
      }
      done = flags[0] != 0;
    }
    if (done) {
      if (!state->stats.empty()) log_line(step);
      if (writes)
        HF_LOG(Info) << options.label << ": stopped at step " << step << " of " << options.steps << ": " << why;
      break;
    }
    if (out_of_time) {
      HF_LOG(Info) << options.label << ": time limit of " << Number(options.max_minutes) << " min reached at step "
                   << step;
      state->out_of_time = true;
      if (options.save_at_time_limit && step < options.steps) HF_RETURN_IF_ERROR(save());
      break;
    }
    if (options.checkpoint_every > 0 && !last && (stop || step % options.checkpoint_every == 0))
      HF_RETURN_IF_ERROR(save());
    if (stop) {
      progress->Finish("interrupted");
      state->seconds = elapsed();
      return Status::Interrupted(options.what + " stopped at step " + std::to_string(step) + " of " +
                                 std::to_string(options.steps) + "; " + options.resume_hint);
    }
  }
  state->seconds = elapsed();
  return Status::Ok();
}

Status OpenTrainStats(const fs::path& out_dir, StatsLog* stats) {
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  std::error_code ec;
  if (!fs::exists(out_dir / "checkpoint.pt", ec) && !fs::exists(out_dir / "decoder_checkpoint.pt", ec))
    HF_RETURN_IF_ERROR(RemoveAll(out_dir / "stats.jsonl"));
  return StatsLog::Open(out_dir / "stats.jsonl", stats);
}

}  // namespace headforge
