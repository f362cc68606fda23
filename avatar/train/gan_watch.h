// A discriminator that tells every real image from every generated one, step
// after step, has won: the generator gets no useful gradient from it, and
// its samples have often collapsed to a few. CollapseWatch counts the
// discriminator steps in a row with both accuracies at 1.0 and says when the
// run reaches `steps`, so the trainers can warn in the log and stats.jsonl.
#pragma once

#include <string>

namespace headforge {

class CollapseWatch {
 public:
  explicit CollapseWatch(int steps) : steps_(steps) {}
  // One discriminator step's accuracies (the share of real images it called
  // real, of generated ones it called generated): true on the step a run of
  // perfect ones reaches `steps`, once per run.
  bool Observe(double real_accuracy, double fake_accuracy) {
    run_ = real_accuracy >= 1.0 && fake_accuracy >= 1.0 ? run_ + 1 : 0;
    return steps_ > 0 && run_ == steps_;
  }
  int run() const { return run_; }
  void set_run(int run) { run_ = run; }  // from a checkpoint
  // The warning's text for `what` (the discriminator's name).
  std::string Warning(const std::string& what) const {
    return what + "'s discriminator has told every real image from every generated one for " +
           std::to_string(steps_) + " steps in a row: the generator is losing, perhaps to mode collapse (see the "
           "previews); lower --lr-discriminator, raise --r1-gamma or --ada-target's augmentation, or stop here";
  }

 private:
  int steps_;
  int run_ = 0;
};

}  // namespace headforge
