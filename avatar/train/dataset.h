// A workspace's capture as the avatar models train on it, read through the
// typed artefacts (capture.json, cameras_head.json, tracking.json): each
// registered view's frame and mask at the training resolution, its camera in
// the canonical head frame (the head's tracked motion taken into the camera),
// the frame's tracked expression and head pose as the condition, and boxes
// round the eyes and the mouth from its landmarks. The last frames are held
// out (or, for one camera circling the head, frames spread over the circle),
// and any cameras named to be.
#pragma once

#include <torch/types.h>

#include <opencv2/core.hpp>

#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "avatar/avatar_train.h"
#include "avatar/splat/splat_camera.h"
#include "avatar/train/dataset_options.h"
#include "avatar/train/hull_masks.h"
#include "core/face_model.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct AvatarView {
  int frame = 0;          // output frame index
  double time_s = 0;      // its time in the capture
  std::string camera;     // its camera's name
  torch::Tensor image;    // [3, H, W] RGB in [0, 1]
  torch::Tensor mask;     // [1, H, W] 1 on the head
  SplatCamera view;       // cam_from_canonical and intrinsics at the training resolution
  torch::Tensor condition;  // [E + 9] expression weights, then the head's pose (below)
  // Left eye, right eye, mouth: (x0, y0, x1, y1) pixels; all zero without landmarks.
  std::array<std::array<float, 4>, 3> regions{};
  // Its landmarks are the face's: found by ingest, and the camera within
  // kLandmarkViewDeg of the face (a detector's points on a head's side or
  // back are not the eyes and mouth); otherwise the view trains appearance
  // only.
  bool has_landmarks = false;
  // The angle (degrees) between the way the tracked face looks and the way
  // to the camera: 0 facing it, 180 from behind.
  double face_angle_deg = 0;
  bool unreliable = false;  // tracking interpolated it or flagged it low-confidence
  bool interpolated = false;  // tracking interpolated it (no landmarks in any view of its frame)
  // The tracked mesh's texture coordinates where it covers the view drawn on
  // a square canvas (MakeSquareCanvas, DatasetOptions::uv_map_side): [3, S,
  // S] uint8, u and v (0..255 over the model's UV range) and covered (255);
  // undefined unless asked for.
  torch::Tensor uv_map;
  // Its frame's tracked mesh [V, 3] (float32, head frame): the expression of
  // `condition` on the identity, computed once for every view of the dataset
  // (AttachViewVertices) instead of at each posing; the views of one frame
  // share it.
  torch::Tensor vertices;
};

// `mask` (CV_8U, 0 / 255) cut to the silhouette of the mesh `vertices` [V,
// 3] (`triangles` [T, 3]) in `camera`, grown outward along the vertex
// normals by `hair` metres where the head's rest shape `rest` [V, 3] lies
// above the eyes (rising from 0 at 55% of its height to `hair` at 70%) and
// by `skin` elsewhere. The camera's size is the mask's.
cv::Mat MeshCutMask(const cv::Mat& mask, const torch::Tensor& vertices, const torch::Tensor& rest,
                    const torch::Tensor& triangles, const SplatCamera& camera, double hair, double skin);

// Views whose camera is further than this from the face's direction carry no
// landmarks (AvatarView::has_landmarks): the tracker's own limit for a
// readable face (TrackOptions::max_yaw_deg).
inline constexpr double kLandmarkViewDeg = 60.0;

struct AvatarDataset {
  int width = 0, height = 0;
  int num_frames = 0;
  int first_test_frame = 0;            // frames from here on are held out
  int holdout_every = 0;               // > 0: so is every frame f with f % holdout_every == holdout_every / 2
  std::vector<AvatarView> train, test;
  // Training frames set aside to choose when training stops (never trained
  // on, never held out): filled by the trainer (SetValidationAside), not by
  // the loader or a pack.
  std::vector<AvatarView> validation;
  std::vector<std::string> expression_names;
  // One camera carried round a head held still (track's still head, a
  // walk-around video): every view shows one state of the head, so every
  // view carries one expression (the median of the views that face the
  // face; its sides and back cannot be tracked) and one latent (frame 0's).
  bool one_state = false;
  int one_state_facing_views = 0;  // the views its expression is the median of (0: every fitted frame's)
  // The masks the views carry: ingest, mesh or hull (DatasetOptions::mask,
  // auto resolved), and the hull's vote when hull.
  std::string mask;
  HullStats hull_stats;
  // The subject's mesh: identity shape [V, 3] (head frame, metres), the
  // expression basis [V * 3, E] and triangles [T, 3] (int64).
  torch::Tensor identity_vertices, expression_basis, triangles;
  // The model's named parts as inclusive triangle ranges (ICT's regions:
  // "face", "head_and_neck", ...; empty for a model without them).
  std::map<std::string, std::pair<int, int>> mesh_parts;

  bool HeldOut(int frame) const { return HoldoutSplit{first_test_frame, holdout_every}.HeldOut(frame); }
  // The frame latent `view` is drawn with in training: its own, or frame 0's
  // when every view shows one state of the head.
  int64_t TrainingLatent(const AvatarView& view) const { return one_state ? 0 : view.frame; }
  // "the last 25 of 125" or "one frame in 5 from frame 2 (30 of 150)".
  std::string HeldOutText() const;

  // The tracked mesh for `expression` [E]: [V, 3].
  torch::Tensor Vertices(const torch::Tensor& expression) const;
  // The same for the rows of `expressions` [N, E] in one product: [N, V, 3].
  torch::Tensor Vertices(const std::vector<torch::Tensor>& expressions) const;
  // The tracked mesh of `view`: its own, or computed from its condition when
  // it has none.
  torch::Tensor Vertices(const AvatarView& view) const;
};

// Sets every view's `vertices` (train, test and validation) that is not set:
// one matrix product for the frames they show, in frame order, so that a
// workspace and a pack of it give the same meshes.
void AttachViewVertices(AvatarDataset* data);

// The training views (indices into data.train) whose tracking the avatar
// may learn expressions from: those neither interpolated nor flagged
// low-confidence. When the flag would leave out more than half of them (a
// rig's views from the sides raise every instant's residual) the flagged
// views come back and only the interpolated ones stay out; `note` then says
// so (else it is cleared).
std::vector<int64_t> UsableTrainingViews(const AvatarDataset& data, std::string* note);

// 8-bit channels [C, H, W] (uint8) -> floats in [0, 1]: every image the
// dataset holds, from a workspace's frames or from a pack, goes through it.
torch::Tensor ImageFromBytes(const torch::Tensor& bytes);

// The pose part of a condition: the head's rotation (its first two columns)
// and translation (metres) relative to what lights it: the camera for
// head-pose cameras (one fixed camera), else the aligned world.
torch::Tensor PoseCondition(const double rotation[9], const double translation[3]);

// `camera` moved round the head frame's origin by `yaw_deg` (toward the
// subject's left, +x) and `pitch_deg` (up, +y), still looking the same way
// relative to the head: a view no camera of the capture had.
SplatCamera OrbitCamera(const SplatCamera& camera, double yaw_deg, double pitch_deg);

// Reads the workspace; clear errors for what is missing or inconsistent
// (no tracking, too few frames, tracking and frames that disagree).
Status LoadAvatarDataset(const fs::path& workspace, const FaceModel& model, const DatasetOptions& options,
                         AvatarDataset* dataset);

}  // namespace headforge
