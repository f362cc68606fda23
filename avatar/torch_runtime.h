// Process-wide LibTorch set-up. Kept free of LibTorch headers so that the
// command-line front end can call it without compiling them.
#pragma once

#include <string>

namespace headforge {

// Sets LibTorch's intra-op thread count (it starts with one on these machines).
void ConfigureTorchThreads(int threads);
// "1.13.0 (CPU)" or "2.4.0 (CUDA, 1 device(s))".
std::string TorchDescription();

}  // namespace headforge
