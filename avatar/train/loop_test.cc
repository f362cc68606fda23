// The training loop's cadence, statistics, divergence check, time limit,
// interrupt and resume, on a trainer whose figures are known step by step.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "avatar/train/checkpoint.h"
#include "avatar/train/loop.h"
#include "core/interrupt.h"

namespace headforge {
namespace {

// Step k gives "loss" = k and, on even steps only, "even" = 10 k; NaN at
// `nan_at`; an interrupt is requested after `interrupt_at`.
class CountingTrainer : public LoopTrainer {
 public:
  void Step(int step, RunningStats* stats) override {
    steps.push_back(step);
    stats->Add("loss", step == nan_at ? std::numeric_limits<double>::quiet_NaN() : double(step));
    if (step % 2 == 0) stats->Add("even", 10.0 * step);
    if (step == warn_at) warning_ = "collapsing";
    if (step == interrupt_at) RequestInterrupt();
  }
  std::string DivergenceAdvice() const override { return "lower the rate"; }
  void Describe(int step, nlohmann::json* line) override { (*line)["described"] = step; }
  bool Boundary(int step) const override { return step == boundary_at; }
  bool Evaluate(int step, nlohmann::json* line) override {
    evaluated.push_back(step);
    (*line)["score"] = 2.0 * step;
    return true;
  }
  Status Preview(int step) override {
    previews.push_back(step);
    return Status::Ok();
  }
  Status Save(const LoopState& state) override {
    saved.push_back(state.step);
    last_saved = Checkpoint();
    state.Save(&last_saved);
    return Status::Ok();
  }
  std::string TakeWarning() override { return std::exchange(warning_, std::string()); }
  bool Done(int step, std::string* why) override {
    if (step != done_at) return false;
    *why = "enough";
    return true;
  }

  int nan_at = -1, warn_at = -1, boundary_at = -1, interrupt_at = -1, done_at = -1;
  std::vector<int> steps, evaluated, previews, saved;
  Checkpoint last_saved;

 private:
  std::string warning_;
};

std::vector<nlohmann::json> Lines(const StatsLog& log) {
  std::vector<nlohmann::json> lines;
  for (const std::string& line : log.lines()) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

LoopOptions Cadence() {
  LoopOptions o;
  o.label = "test";
  o.steps = 10;
  o.log_every = 4;
  o.eval_every = 5;
  o.preview_every = 3;
  o.checkpoint_every = 4;
  o.tags = {{"stage", 7}};
  return o;
}

TEST(TrainingLoop, KeepsItsCadenceAndAveragesEachFigureOverTheStepsThatGaveIt) {
  CountingTrainer trainer;
  trainer.boundary_at = 6;
  trainer.warn_at = 2;
  LoopState state;
  StatsLog log;
  NullProgress progress;
  ASSERT_TRUE(RunLoop(Cadence(), &trainer, &state, &log, &progress).ok());
  EXPECT_EQ(state.step, 10);
  EXPECT_EQ(trainer.steps, (std::vector<int>{1, 2, 3, 4, 5, 6, 7, 8, 9, 10}));
  EXPECT_EQ(trainer.evaluated, (std::vector<int>{5}));           // never on the last step
  EXPECT_EQ(trainer.previews, (std::vector<int>{3, 6, 9}));      // 6 is also the boundary: once
  EXPECT_EQ(trainer.saved, (std::vector<int>{4, 8}));            // never after the last step
  const std::vector<nlohmann::json> lines = Lines(log);
  // The warning at 2, logs at 4, eval at 5, the boundary's log at 6, logs at 8 and 10.
  ASSERT_EQ(lines.size(), 6u);
  EXPECT_EQ(lines[0]["warning"], "collapsing");
  EXPECT_EQ(lines[0]["step"], 2);
  EXPECT_DOUBLE_EQ(lines[1]["loss"].get<double>(), 2.5);   // (1 + 2 + 3 + 4) / 4
  EXPECT_DOUBLE_EQ(lines[1]["even"].get<double>(), 30.0);  // (20 + 40) / 2
  EXPECT_EQ(lines[1]["described"], 4);
  EXPECT_EQ(lines[1]["stage"], 7);
  EXPECT_DOUBLE_EQ(lines[2]["score"].get<double>(), 10.0);
  EXPECT_FALSE(lines[2].contains("loss"));
  EXPECT_EQ(lines[3]["step"], 6);
  EXPECT_DOUBLE_EQ(lines[3]["loss"].get<double>(), 5.5);  // steps 5 and 6
  EXPECT_EQ(lines[5]["step"], 10);
  EXPECT_DOUBLE_EQ(lines[5]["loss"].get<double>(), 9.5);
  for (size_t i = 1; i < lines.size(); ++i) EXPECT_TRUE(lines[i].contains("seconds")) << lines[i];
}

TEST(TrainingLoop, ANonFiniteFigureEndsTrainingAndNamesIt) {
  CountingTrainer trainer;
  trainer.nan_at = 7;
  LoopState state;
  StatsLog log;
  NullProgress progress;
  const Status s = RunLoop(Cadence(), &trainer, &state, &log, &progress);
  EXPECT_EQ(s.code(), Status::Code::kInternal);
  EXPECT_NE(s.message().find("loss became nan at step 7"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("lower the rate"), std::string::npos) << s.message();
  EXPECT_EQ(state.step, 6);
}

TEST(TrainingLoop, StopsAtTheTimeLimitWithALastLine) {
  CountingTrainer trainer;
  LoopOptions options = Cadence();
  options.max_minutes = 1e-9;
  LoopState state;
  StatsLog log;
  NullProgress progress;
  ASSERT_TRUE(RunLoop(options, &trainer, &state, &log, &progress).ok());
  EXPECT_EQ(state.step, 1);
  ASSERT_EQ(log.size(), 1u);
  EXPECT_DOUBLE_EQ(Lines(log)[0]["loss"].get<double>(), 1.0);
  EXPECT_TRUE(trainer.saved.empty());
}

TEST(TrainingLoop, ATrainerThatIsDoneEndsItWithTheStepsFiguresLogged) {
  CountingTrainer trainer;
  trainer.done_at = 6;
  LoopState state;
  StatsLog log;
  NullProgress progress;
  ASSERT_TRUE(RunLoop(Cadence(), &trainer, &state, &log, &progress).ok());
  EXPECT_EQ(state.step, 6);
  EXPECT_EQ(trainer.steps.back(), 6);
  const std::vector<nlohmann::json> lines = Lines(log);
  // Logs at 4, the evaluation at 5, then the figures of steps 5 and 6 at the stop.
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[2]["step"], 6);
  EXPECT_DOUBLE_EQ(lines[2]["loss"].get<double>(), 5.5);
  EXPECT_EQ(trainer.saved, (std::vector<int>{4}));
}

TEST(TrainingLoop, AnInterruptSavesAndTheResumedRunWritesWhatOneRunWould) {
  NullProgress progress;
  CountingTrainer whole;
  LoopState whole_state;
  StatsLog whole_log;
  ASSERT_TRUE(RunLoop(Cadence(), &whole, &whole_state, &whole_log, &progress).ok());

  CountingTrainer first;
  first.interrupt_at = 6;
  LoopState state;
  StatsLog log;
  {
    InterruptScope scope;
    const Status s = RunLoop(Cadence(), &first, &state, &log, &progress);
    EXPECT_EQ(s.code(), Status::Code::kInterrupted);
    EXPECT_NE(s.message().find("training stopped at step 6 of 10"), std::string::npos) << s.message();
  }
  ASSERT_EQ(first.saved, (std::vector<int>{4, 6}));
  // The checkpoint through a file, as a resumed process reads it.
  const fs::path file = fs::temp_directory_path() / "headforge_loop_test.pt";
  ASSERT_TRUE(first.last_saved.Save(file).ok());
  Checkpoint read;
  ASSERT_TRUE(Checkpoint::Load(file, &read).ok());
  fs::remove(file);
  LoopState resumed;
  ASSERT_TRUE(resumed.Load(read));
  EXPECT_EQ(resumed.step, 6);
  ASSERT_TRUE(log.Truncate(resumed.stats_lines).ok());
  CountingTrainer second;
  ASSERT_TRUE(RunLoop(Cadence(), &second, &resumed, &log, &progress).ok());
  EXPECT_EQ(second.steps, (std::vector<int>{7, 8, 9, 10}));
  const std::vector<nlohmann::json> a = Lines(whole_log), b = Lines(log);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    nlohmann::json x = a[i], y = b[i];
    x.erase("seconds");
    y.erase("seconds");
    EXPECT_EQ(x, y) << i;
  }
}

TEST(TrainingLoop, RunningStatsSurviveACheckpointAndRefuseADamagedOne) {
  RunningStats stats;
  stats.Add("a b", 1.0);
  stats.Add("a b", 3.0);
  stats.Add("c", -2.0);
  Checkpoint c;
  stats.Save("s.", &c);
  RunningStats back;
  ASSERT_TRUE(back.Load("s.", c));
  nlohmann::json line;
  back.TakeMeans(&line);
  EXPECT_DOUBLE_EQ(line["a b"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(line["c"].get<double>(), -2.0);
  EXPECT_TRUE(back.empty());
  Checkpoint damaged;
  damaged.Put("s.count", int64_t(3));
  EXPECT_FALSE(back.Load("s.", damaged));
  LoopState state;
  EXPECT_FALSE(state.Load(damaged));
}

}  // namespace
}  // namespace headforge
