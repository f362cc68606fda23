// A [3, H, W] RGB tensor in [0, 1] (clamped) written as a PNG file,
// atomically, for the trainers' previews and held-out images. A LibTorch-only
// build (HEADFORGE_SPLAT_ONLY) has no image library: there nothing is
// written, and ImageFilesWritten() says so.
#pragma once

#include <torch/types.h>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

Status WriteTensorImage(const fs::path& path, const torch::Tensor& rgb);
bool ImageFilesWritten();

}  // namespace headforge
