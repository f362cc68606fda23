// Which views of a workspace an avatar trains on and how they are read
// (LoadAvatarDataset, dataset.h): the training size, the held-out frames and
// cameras, and the head masks. No LibTorch here: train's options
// (avatar_train.h) hold one, and pipelines/ reads them.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <string>
#include <vector>

#include "core/status.h"

namespace headforge {

// Both models train on at least this many frames besides those held out.
constexpr int kFewestTrainingFrames = 8;

struct DatasetOptions {
  int resolution = 256;       // the frames' longer side, pixels
  double holdout = 0.2;       // the fraction of the frames held out
  // Which: "last" (the last frames: the capture's future), "interleaved"
  // (every round(1 / holdout)-th frame: views between training views) or
  // "auto" (interleaved for one camera whose views spread 120 degrees or more
  // round the head, where the last frames would be a side training never
  // saw; else last).
  std::string holdout_order = "auto";
  // Cameras held out whole: every frame of theirs is a test view (a 360
  // capture's views from sides training never saw).
  std::vector<std::string> holdout_cameras;
  // The head masks the models train and are scored on: "ingest" (the
  // workspace's masks as they are) or "mesh" (the workspace's masks cut to
  // the tracked mesh's silhouette grown by `mask_hair` metres over the scalp
  // and `mask_skin` elsewhere: face, ears, neck): GrabCut takes background of the skin's
  // colour beside the head for the head. Nothing is added: the mesh reaches
  // below the frame's edge (the neck, the shoulders) where a crop was padded.
  // On talking_static at 128 px the skin's margin against the simulator's
  // masks (mean IoU; GrabCut's alone 0.963): 2 mm 0.959, 6 mm 0.966, 12 mm
  // 0.973, 16 mm 0.976, 24 mm 0.975; the tracked mesh is a pixel or two off.
  // "hull" (one camera carried round a still head, AvatarDataset::one_state):
  // the workspace's masks made to agree across the views (hull_masks.h), the
  // training views voting. "auto": hull for such a capture, else `auto_mask`
  // (the model's own: TrainOptions::DataFor).
  std::string mask = "ingest";
  std::string auto_mask = "ingest";
  double mask_hair = 0.03;
  double mask_skin = 0.016;

  // How a load reads the views; not options of train's, and not recorded.
  int min_train_frames = kFewestTrainingFrames;  // fewer is refused
  bool images = true;         // false: cameras and conditions only (rendering)
  int uv_map_side = 0;        // > 0: the training views' UV maps on a canvas this side (stage 3)

  // Train's checks of these options (the messages name train's flags).
  Status Check() const;
};

// The options above that train records (every one but the load's own three)
// by their field names; reading keeps the value of a field `j` lacks.
nlohmann::json ToJson(const DatasetOptions& options);
void FromJson(const nlohmann::json& j, DatasetOptions* options);

// How many of `frames` training holds out: the last round(holdout x frames)
// (one at least), or, interleaved, every HoldoutStride(holdout)-th from the
// middle of the first stride (DatasetOptions::holdout_order).
int HeldOutFrames(int frames, double holdout, bool interleaved);
// The interleaved hold-out's stride: round(1 / holdout), 2 at least.
int HoldoutStride(double holdout);

// Which of a capture's frames training holds out: every frame from
// first_test_frame on and, with `every` > 0 (interleaved), every frame f
// with f % every == every / 2.
struct HoldoutSplit {
  int first_test_frame = 0;
  int every = 0;
  bool HeldOut(int frame) const { return frame >= first_test_frame || (every > 0 && frame % every == every / 2); }
};
// The split HeldOutFrames counts: the last ones, or interleaved.
HoldoutSplit SplitFrames(int frames, double holdout, bool interleaved);
// Whether the hold-out is interleaved: --holdout-order interleaved, or auto
// on a capture whose camera walks round the head (CameraSet::WalksRoundTheHead).
bool HoldoutInterleaved(const std::string& holdout_order, bool walks_round_the_head);

}  // namespace headforge
