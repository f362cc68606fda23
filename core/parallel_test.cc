// ParallelFor visits every index once and rethrows; DefaultThreads reads
// $HEADFORGE_THREADS and ignores what is not a positive count.
#include "core/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace headforge {
namespace {

TEST(ParallelFor, VisitsEveryIndexOnceAndRethrows) {
  std::vector<std::atomic<int>> seen(257);
  ParallelFor(257, 3, [&](int i, int worker) {
    EXPECT_GE(worker, 0);
    EXPECT_LT(worker, 3);
    seen[size_t(i)]++;
  });
  for (const auto& s : seen) EXPECT_EQ(s.load(), 1);
  EXPECT_THROW(ParallelFor(10, 2, [](int i, int) {
                 if (i == 7) throw std::runtime_error("seven");
               }),
               std::runtime_error);
}

TEST(DefaultThreads, TakesTheEnvironmentsCountOrEveryHardwareThread) {
  const char* saved = std::getenv("HEADFORGE_THREADS");
  const std::string kept = saved ? saved : "";
  ::unsetenv("HEADFORGE_THREADS");
  EXPECT_EQ(DefaultThreads(), HardwareThreads());
  ::setenv("HEADFORGE_THREADS", "3", 1);
  EXPECT_EQ(DefaultThreads(), 3);
  for (const char* bad : {"0", "-2", "two", "3x", ""}) {
    ::setenv("HEADFORGE_THREADS", bad, 1);
    EXPECT_EQ(DefaultThreads(), HardwareThreads()) << "'" << bad << "'";
  }
  if (saved) {
    ::setenv("HEADFORGE_THREADS", kept.c_str(), 1);
  } else {
    ::unsetenv("HEADFORGE_THREADS");
  }
}

}  // namespace
}  // namespace headforge
