// Person masks made to agree across calibrated views of one still shape (a
// camera carried round a head held still): each view's matte votes on a grid
// of points round the head, the points most views keep form the shape (its
// visual hull by vote, without small pieces apart from it), and each view's mask becomes that shape's silhouette
// with the matte's own edge where the two agree. A matte that took the
// background beside the head, or lost the face, in a few views is put right
// by the others. Torch-free: OpenCV and Eigen.
#pragma once

#include <opencv2/core.hpp>

#include <vector>

#include "avatar/splat/splat_camera.h"
#include "core/status.h"

namespace headforge {

struct HullOptions {
  // The box of points voted on, in the head frame (metres): x and z within
  // +-half_width, y from `bottom` to `top` (+y up), on a grid of `voxel`.
  double half_width = 0.3, bottom = -0.45, top = 0.3;
  double voxel = 0.005;
  // A point is kept when at least `min_views` views see it (its projection
  // inside their frame) and at least this share of them have it inside
  // their mask: first `vote` of every voter (lenient: a few failed mattes
  // cannot take the shape apart), then `strict_vote` of the voters whose
  // masks agree with that shape's silhouette (`agree_spread`), which trims what
  // only the views seeing it edge-on rule out. 0.9 against 0.95: the
  // mattes' ragged edge where the bust meets the background cut its lower
  // part off at 0.95 (walkaround_360, 150 views: the training views' masks
  // 0.882 -> 0.905 IoU against the simulator's; 0.925 0.901, 0.85 0.895, 0.8 0.877).
  double vote = 0.7, strict_vote = 0.9;
  int min_views = 3;
  // Within this many pixels of the shape's silhouette edge the matte decides
  // (its soft edge kept); further inside the silhouette is the person,
  // further outside is not.
  int edge_px = 3;
  // The second vote's voters: those whose masks agree (IoU) with the first
  // shape's silhouette within `agree_spread` of the voters' median. And a
  // view whose mask agrees with the final silhouette less than `agree`
  // takes the silhouette whole: its matte failed there.
  double agree_spread = 0.05;
  double agree = 0.9;
  // Pieces of the shape (6-connected grid points) smaller than this share of
  // the largest are dropped: a head and its bust are one or two large pieces.
  double min_piece = 0.05;

  Status Check() const;
};

struct HullStats {
  int views = 0;             // the views that voted
  int agreeing = 0;          // of them, those whose masks agreed with the lenient vote's shape
  int replaced = 0;          // views whose mask gave way to the silhouette whole (HullOptions::agree)
  int64_t kept_points = 0;   // the grid points kept
  int64_t dropped_points = 0;  // voted in, but in a piece under min_piece of the largest, and dropped
  int64_t grid_points = 0;
};

// `masks[i]` (CV_8U, 0..255, the size of `cameras[i]`) of views of one still
// shape through `cameras[i]` (cam_from_world: the head frame): `voters`
// (indices) vote, and every view's mask is remade into `out` (the same sizes).
// Errors: fewer than `min_views` voters, masks and cameras that disagree, or
// no point kept.
Status HullMasks(const std::vector<SplatCamera>& cameras, const std::vector<cv::Mat>& masks,
                 const std::vector<int>& voters, const HullOptions& options, std::vector<cv::Mat>* out,
                 HullStats* stats = nullptr);

}  // namespace headforge
