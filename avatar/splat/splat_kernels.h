// Backend kernels behind splat_ops.h; one set per device, same arguments.
// Inputs are validated and made contiguous by splat_ops.cc, outputs are
// allocated there. Internal to avatar/.
#pragma once

#include <torch/types.h>

#include "avatar/splat/splat_params.h"

namespace headforge::splat {

namespace cpu {
#include "avatar/splat/splat_backend.inc"
}  // namespace cpu

#ifdef HEADFORGE_WITH_CUDA
// Same arguments, tensors on one CUDA device (splat_cuda.cc).
namespace cuda {
#include "avatar/splat/splat_backend.inc"
}  // namespace cuda
#endif

}  // namespace headforge::splat
