#include "avatar/train/dataset_options.h"

#include <algorithm>
#include <cmath>

namespace headforge {

int HoldoutStride(double holdout) { return std::max(2, int(std::lround(1 / holdout))); }

int HeldOutFrames(int frames, double holdout, bool interleaved) {
  if (!interleaved) return std::max(1, int(std::lround(holdout * frames)));
  const int every = HoldoutStride(holdout);
  int held = 0;
  for (int f = 0; f < frames; ++f) held += f % every == every / 2;
  return held;
}

}  // namespace headforge
