// Process-wide LibTorch set-up. Kept free of LibTorch headers so that the
// command-line front end can call it without compiling them.
#pragma once

#include <string>

namespace headforge {

// Records the thread count for tensor work and leaves OpenMP, which
// LibTorch, OpenBLAS, Eigen and CHOLMOD share, on one thread until
// UseTensorThreads: the Ceres stages' small dense and sparse solves run
// several times slower threaded.
void ConfigureTorchThreads(int threads);
// Keeps the memory that freed tensors leave in the process for the next
// ones: every block comes from the heap, and the heap keeps up to 1 GiB
// freed, where glibc's malloc would map and unmap each block over its
// threshold afresh and trim the heap's top. A training step allocates and
// frees the same large blocks many times, and faulting their pages back in
// each time took up to two thirds of a CPU step (docs/benchmarks.md).
// Resident memory stays near the peak. The CLI and headforge-train call it
// once at start; $HEADFORGE_MALLOC=system leaves glibc's defaults and
// =threshold maps blocks over 32 MiB afresh (both to compare).
void KeepFreedTensorMemory();
// Gives LibTorch and the BLAS the recorded count, for the models' large
// products: training, rendering and splat-fit call it as their tensor work begins.
void UseTensorThreads();
// The recorded count (--threads, resolved): for CPU work beside the tensors'.
int TensorThreads();
// "1.13.0 (CPU)" or "2.4.0 (CUDA, 1 device(s))".
std::string TorchDescription();

}  // namespace headforge
