// A small parallel loop for per-item work (frames, views) that is not tensor math.
#pragma once

#include <functional>

namespace headforge {

// Number of hardware threads (at least 1).
int HardwareThreads();

// Threads for work whose `threads` option is 0: $HEADFORGE_THREADS when it
// holds a positive number (a shared machine, or tests run side by side),
// else HardwareThreads().
int DefaultThreads();

// Calls fn(index, worker) for index in [0, count) on `threads` workers; each
// worker has its own `worker` id in [0, threads) for per-thread state. The first
// exception thrown by fn is rethrown here after all workers stop.
void ParallelFor(int count, int threads, const std::function<void(int index, int worker)>& fn);

// Threads OpenBLAS gives each call (a no-op with another BLAS); see
// ConfigureTorchThreads (avatar/torch_runtime.h) for who sets it.
void SetBlasThreads(int threads);

}  // namespace headforge
