#include "core/interrupt.h"

#include <signal.h>

#include <atomic>

namespace headforge {
namespace {

std::atomic<bool> g_requested{false};
int g_depth = 0;  // nested scopes; only the outermost installs and restores handlers
struct sigaction g_previous_int, g_previous_term;

void OnSignal(int signal) {
  if (g_requested.exchange(true)) {
    // Asked twice: stop now, the way the signal would have without us.
    ::signal(signal, SIG_DFL);
    ::raise(signal);
  }
}

}  // namespace

InterruptScope::InterruptScope() {
  if (g_depth++ > 0) return;
  g_requested = false;
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, &g_previous_int);
  sigaction(SIGTERM, &action, &g_previous_term);
}

InterruptScope::~InterruptScope() {
  if (--g_depth > 0) return;
  sigaction(SIGINT, &g_previous_int, nullptr);
  sigaction(SIGTERM, &g_previous_term, nullptr);
  g_requested = false;
}

bool InterruptRequested() { return g_requested.load(std::memory_order_relaxed); }

void RequestInterrupt() { g_requested = true; }

}  // namespace headforge
