// Locating and probing the `colmap` executable that the calibrate stage runs
// as a subprocess (headless, CPU SIFT).
#pragma once

#include <string>

#include "core/status.h"

namespace headforge {

// Runs `executable -h` and extracts its version line ("COLMAP 3.8"). NotFound
// when it cannot be run.
Status ColmapVersion(const std::string& executable, std::string* version);

}  // namespace headforge
