#include "core/progress.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>

namespace headforge {
namespace {

// The seconds a plain progress line says are left ("~N s left"), or -1.
double SaidLeft(const std::string& text) {
  const size_t end = text.rfind(" s left");
  if (end == std::string::npos) return -1;
  const size_t begin = text.rfind('~', end);
  return begin == std::string::npos ? -1 : std::stod(text.substr(begin + 1, end - begin - 1));
}

// A task with a time limit never says more time left than the limit
// leaves; without one, the time left follows its rate.
TEST(StderrProgress, TimeLeftIsNeverPastTheTimeLimit) {
  for (const bool limited : {false, true}) {
    StderrProgress progress(std::chrono::seconds(0));
    progress.set_force_plain(true);
    testing::internal::CaptureStderr();
    progress.Start("task", 1000);
    if (limited) progress.LimitTime(3.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    progress.Advance(1);  // about 50 s left at this rate
    progress.Finish();
    const std::string text = testing::internal::GetCapturedStderr();
    const double left = SaidLeft(text);
    ASSERT_GE(left, 0) << text;
    if (limited) {
      EXPECT_LE(left, 3.0) << text;
    } else {
      EXPECT_GT(left, 10.0) << text;
    }
  }
}

}  // namespace
}  // namespace headforge
