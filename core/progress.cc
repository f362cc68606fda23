#include "core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/log.h"

namespace headforge {

StderrProgress::StderrProgress(std::chrono::seconds interval)
    : plain_(!isatty(STDERR_FILENO)), interval_(interval) {}

namespace {
// Progress is information: silenced with the info log level.
bool Quiet() { return GetLogLevel() > LogLevel::kInfo; }
}  // namespace

void StderrProgress::Start(const std::string& label, int64_t total) {
  if (Quiet()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  label_ = label;
  total_ = total;
  done_ = 0;
  resumed_ = 0;
  limit_ = 0;
  last_quarter_ = 0;
  start_ = last_print_ = std::chrono::steady_clock::now();
  // A task of unknown length (total 0) says no count.
  if (plain_ && total_ > 0)
    std::fprintf(stderr, "[headforge] %s: started (%lld)\n", label_.c_str(), static_cast<long long>(total_));
  else if (plain_)
    std::fprintf(stderr, "[headforge] %s: started\n", label_.c_str());
}

void StderrProgress::Advance(int64_t units) {
  if (Quiet()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  done_ += units;
  Draw(false);
}

void StderrProgress::Resume(int64_t units) {
  if (Quiet()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  done_ += units;
  resumed_ += units;
}

void StderrProgress::LimitTime(double seconds) {
  if (Quiet()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  limit_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count() + std::max(0.0, seconds);
}

double StderrProgress::SecondsLeft(double elapsed) const {
  const int64_t now = done_ - resumed_;
  const double at_rate = now > 0 && total_ > done_ ? elapsed * double(total_ - done_) / double(now) : 0.0;
  return limit_ > 0 && at_rate > 0 ? std::min(at_rate, std::max(0.0, limit_ - elapsed)) : at_rate;
}

void StderrProgress::Finish(const std::string& summary) {
  if (Quiet()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (!plain_) std::fprintf(stderr, "\r\033[K");
  const std::string count = total_ > 0 || done_ > 0 ? " " + std::to_string(done_) : "";
  std::fprintf(stderr, "[headforge] %s: done%s in %.1f s%s%s\n", label_.c_str(), count.c_str(), seconds,
               summary.empty() ? "" : ", ", summary.c_str());
  std::fflush(stderr);
}

void StderrProgress::Draw(bool final_line) {
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double fraction = total_ > 0 ? static_cast<double>(done_) / total_ : 0.0;
  if (plain_) {
    const int quarter = static_cast<int>(fraction * 4.0);
    if (quarter <= last_quarter_ && now - last_print_ < interval_) return;
    last_quarter_ = std::max(quarter, last_quarter_);
    last_print_ = now;
    const double left = SecondsLeft(elapsed);
    const std::string eta = left > 0 ? ", ~" + std::to_string(std::lround(left)) + " s left" : "";
    if (total_ > 0)
      std::fprintf(stderr, "[headforge] %s: %lld/%lld (%.0f%%), %.1f s%s\n", label_.c_str(),
                   static_cast<long long>(done_), static_cast<long long>(total_), 100.0 * fraction, elapsed,
                   eta.c_str());
    else
      std::fprintf(stderr, "[headforge] %s: %lld, %.1f s\n", label_.c_str(),
                   static_cast<long long>(done_), elapsed);
    return;
  }
  // Redraw at most ~10 times a second.
  if (!final_line && now - last_print_ < std::chrono::milliseconds(100) && done_ != total_) return;
  last_print_ = now;
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(fraction * kWidth);
  char bar[kWidth + 1];
  for (int i = 0; i < kWidth; ++i) bar[i] = i < filled ? '#' : '.';
  bar[kWidth] = '\0';
  const double eta = SecondsLeft(elapsed);
  std::fprintf(stderr, "\r\033[K%s [%s] %lld/%lld  %.1f s elapsed, ~%.0f s left", label_.c_str(),
               bar, static_cast<long long>(done_), static_cast<long long>(total_), elapsed, eta);
  std::fflush(stderr);
}

}  // namespace headforge
