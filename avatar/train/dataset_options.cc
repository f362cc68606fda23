#include "avatar/train/dataset_options.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace headforge {

Status DatasetOptions::Check() const {
  if (resolution < 16 || resolution > 4096) return Status::InvalidArgument("train: --train-size must be in [16, 4096]");
  if (!(holdout > 0 && holdout < 0.9)) return Status::InvalidArgument("train: --holdout must be in (0, 0.9)");
  if (holdout_order != "auto" && holdout_order != "last" && holdout_order != "interleaved")
    return Status::InvalidArgument("train: --holdout-order must be auto, last or interleaved, not '" + holdout_order +
                                   "'");
  if (mask != "auto" && mask != "ingest" && mask != "mesh" && mask != "hull")
    return Status::InvalidArgument("train: --mask must be auto, ingest, mesh or hull, not '" + mask +
                                   "' (your own masks: a folder given to ingest's --mask-folder)");
  if (!(mask_hair >= 0 && mask_hair <= 0.3) || !(mask_skin >= 0 && mask_skin <= 0.3))
    return Status::InvalidArgument("train: --mask-hair and --mask-skin must be in [0, 0.3] metres");
  return Status::Ok();
}

nlohmann::json ToJson(const DatasetOptions& o) {
  return {{"resolution", o.resolution},
          {"holdout", o.holdout},
          {"holdout_order", o.holdout_order},
          {"holdout_cameras", o.holdout_cameras},
          {"mask", o.mask},
          {"mask_hair", o.mask_hair},
          {"mask_skin", o.mask_skin}};
}

void FromJson(const nlohmann::json& j, DatasetOptions* o) {
  o->resolution = j.value("resolution", o->resolution);
  o->holdout = j.value("holdout", o->holdout);
  o->holdout_order = j.value("holdout_order", o->holdout_order);
  o->holdout_cameras = j.value("holdout_cameras", o->holdout_cameras);
  o->mask = j.value("mask", o->mask);
  o->mask_hair = j.value("mask_hair", o->mask_hair);
  o->mask_skin = j.value("mask_skin", o->mask_skin);
}

int HoldoutStride(double holdout) { return std::max(2, int(std::lround(1 / holdout))); }

int HeldOutFrames(int frames, double holdout, bool interleaved) {
  if (!interleaved) return std::max(1, int(std::lround(holdout * frames)));
  const int every = HoldoutStride(holdout);
  int held = 0;
  for (int f = 0; f < frames; ++f) held += f % every == every / 2;
  return held;
}

bool HoldoutInterleaved(const std::string& holdout_order, bool walks_round_the_head) {
  return holdout_order == "interleaved" || (holdout_order == "auto" && walks_round_the_head);
}

HoldoutSplit SplitFrames(int frames, double holdout, bool interleaved) {
  HoldoutSplit split;
  if (interleaved) {
    split.every = HoldoutStride(holdout);
    split.first_test_frame = frames;
  } else {
    split.first_test_frame = frames - HeldOutFrames(frames, holdout, false);
  }
  return split;
}

}  // namespace headforge
