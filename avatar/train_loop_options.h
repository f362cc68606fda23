// The training loop's cadence (loop.h) from train's options: every model's
// loops log, evaluate, preview, checkpoint and stop at the time limit alike.
#pragma once

#include <string>

#include "avatar/avatar_train.h"
#include "avatar/train/loop.h"

namespace headforge {

// --max-minutes, --log-every, --eval-every, --preview-every and
// --checkpoint-every for a loop of `steps` steps shown as `label`.
LoopOptions TrainLoopOptions(const TrainLoopSettings& settings, const std::string& label, int steps);

}  // namespace headforge
