#include "avatar/train/loop.h"

#include "core/interrupt.h"

namespace headforge {

Status CheckpointOrStop(const std::string& what, int step, int steps, bool last, int every,
                        const std::function<Status()>& save, Progress* progress) {
  const bool stop = InterruptRequested();
  if (!last && (stop || step % every == 0)) HF_RETURN_IF_ERROR(save());
  if (!stop) return Status::Ok();
  progress->Finish("interrupted");
  return Status::Interrupted(what + " stopped at step " + std::to_string(step) + " of " + std::to_string(steps) +
                             "; the checkpoint is saved: run the same command again to resume");
}

}  // namespace headforge
