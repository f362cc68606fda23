// A request to stop, for long work that can save its state first (training,
// fitting). While an InterruptScope is alive, SIGINT and SIGTERM set a flag
// instead of ending the process; the loop polls InterruptRequested(), writes
// its checkpoint and returns Status::Interrupted. A second signal of the same
// kind ends the process as usual (for a loop that stopped polling).
#pragma once

namespace headforge {

class InterruptScope {
 public:
  InterruptScope();
  ~InterruptScope();
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;
};

// True once SIGINT or SIGTERM arrived inside an InterruptScope (or after
// RequestInterrupt); cleared when the outermost scope ends.
bool InterruptRequested();
// The same request made from code (tests, a time limit).
void RequestInterrupt();

}  // namespace headforge
