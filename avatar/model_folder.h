// Which of a workspace's trained models export, the report and render take
// when not told. No LibTorch here: export/ includes it.
#pragma once

#include "core/fs.h"

namespace headforge {

// Of WORKSPACE/models/gaussian_style and models/gan_avatar, the one trained
// last (its config.json the newer); empty when neither is trained.
fs::path LatestModelFolder(const fs::path& workspace);

}  // namespace headforge
