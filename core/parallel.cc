#include "core/parallel.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace headforge {

int HardwareThreads() { return std::max(1u, std::thread::hardware_concurrency()); }

int DefaultThreads() {
  if (const char* env = std::getenv("HEADFORGE_THREADS")) {
    char* end = nullptr;
    const long n = std::strtol(env, &end, 10);
    if (end != env && *end == '\0' && n > 0) return static_cast<int>(std::min<long>(n, 1024));
  }
  return HardwareThreads();
}

void ParallelFor(int count, int threads, const std::function<void(int, int)>& fn) {
  threads = std::max(1, std::min(threads, count));
  if (threads <= 1) {
    for (int i = 0; i < count; ++i) fn(i, 0);
    return;
  }
  std::atomic<int> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&](int worker) {
    for (;;) {
      const int i = next++;
      if (i >= count) return;
      try {
        fn(i, worker);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = count;  // stop handing out work
      }
    }
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < threads; ++w) pool.emplace_back(work, w);
  work(0);
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

void SetBlasThreads(int threads) {
  // Looked up at run time: the BLAS is whichever Debian's alternatives chose.
  using SetThreads = void (*)(int);
  static const auto set = reinterpret_cast<SetThreads>(::dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (set) set(std::max(1, threads));
}

}  // namespace headforge
