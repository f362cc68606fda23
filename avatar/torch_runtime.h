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
// Gives LibTorch and the BLAS the recorded count, for the models' large
// products: training, rendering and splat-fit call it as their tensor work begins.
void UseTensorThreads();
// The recorded count (--threads, resolved): for CPU work beside the tensors'.
int TensorThreads();
// "1.13.0 (CPU)" or "2.4.0 (CUDA, 1 device(s))".
std::string TorchDescription();

}  // namespace headforge
