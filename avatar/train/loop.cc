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

Status OpenTrainStats(const fs::path& out_dir, StatsLog* stats) {
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  std::error_code ec;
  if (!fs::exists(out_dir / "checkpoint.pt", ec) && !fs::exists(out_dir / "decoder_checkpoint.pt", ec))
    HF_RETURN_IF_ERROR(RemoveAll(out_dir / "stats.jsonl"));
  return StatsLog::Open(out_dir / "stats.jsonl", stats);
}

}  // namespace headforge
