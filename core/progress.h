// Progress reporting for long work. Library code reports through a Progress it
// is given; the command-line tool passes one that draws on stderr.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

namespace headforge {

class Progress {
 public:
  virtual ~Progress() = default;
  // Begins a task of `total` units (0: unknown). Safe to call again for the next task.
  virtual void Start(const std::string& label, int64_t total) = 0;
  // Adds `units` done; callable from several threads.
  virtual void Advance(int64_t units = 1) = 0;
  // Counts `units` an earlier, interrupted attempt did (a resumed task):
  // done, but not in this attempt's rate.
  virtual void Resume(int64_t units) { Advance(units); }
  // The current task stops within `seconds` from now whatever its count (a
  // time limit): the time said to be left is never more.
  virtual void LimitTime(double seconds) {}
  // Ends the current task with a closing line.
  virtual void Finish(const std::string& summary = "") = 0;
};

// Reports nothing.
class NullProgress : public Progress {
 public:
  void Start(const std::string&, int64_t) override {}
  void Advance(int64_t) override {}
  void Finish(const std::string&) override {}
};

// Draws a redrawn bar when stderr is a terminal; otherwise prints a plain line
// at most every `interval` (and at 25% steps), so logs stay readable.
class StderrProgress : public Progress {
 public:
  explicit StderrProgress(std::chrono::seconds interval = std::chrono::seconds(5));
  // Overrides the terminal test (for tests and piping).
  void set_force_plain(bool plain) { plain_ = plain; }

  void Start(const std::string& label, int64_t total) override;
  void Advance(int64_t units = 1) override;
  void Resume(int64_t units) override;
  void LimitTime(double seconds) override;
  void Finish(const std::string& summary = "") override;

 private:
  // Seconds left at this attempt's rate (0 when it has none yet).
  double SecondsLeft(double elapsed) const;
  void Draw(bool final_line);

  std::mutex mutex_;
  std::string label_;
  int64_t total_ = 0;
  int64_t done_ = 0;
  int64_t resumed_ = 0;  // of done_, what an earlier attempt did
  double limit_ = 0;     // > 0: seconds after start_ at which the task stops (LimitTime)
  int last_quarter_ = 0;
  bool plain_;
  std::chrono::seconds interval_;
  std::chrono::steady_clock::time_point start_, last_print_;
};

}  // namespace headforge
