// Structure from motion with the real `colmap` executable, run headless with
// CPU SIFT on the ingested frames: feature extraction with one shared camera
// per video, sequential (one video) or exhaustive (several) matching, the
// incremental mapper; the largest model is converted to text and read back.
#pragma once

#include <map>
#include <string>
#include <utility>

#include "core/camera_set.h"
#include "capture/capture_io.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct ColmapOptions {
  std::string executable;                 // the colmap program
  std::string camera_model = "SIMPLE_RADIAL";  // SIMPLE_RADIAL, RADIAL, OPENCV or PINHOLE
  int max_features = 4096;                // SIFT features per image
  std::string matcher = "auto";           // auto (sequential for one video, else exhaustive), sequential, exhaustive
  int overlap = 10;                       // sequential matcher: neighbours per image
  // Which pixels COLMAP may use: "none" (all), "background" (not the head:
  // for a head that moves or deforms between frames), "head" (only the head),
  // "auto" (background when several cameras watch a moving head, else none).
  std::string mask = "auto";
  int frame_step = 1;                     // use every n-th frame
  // Cameras that do not move (a rig): COLMAP sees `rig_instants` synchronised
  // frames per camera, with the head unmasked (at one instant it is as still
  // as the room), and each camera's pose is given to all its frames.
  bool static_cameras = false;
  int rig_instants = 1;
  int threads = 0;                        // 0: all
  // Mapper runs: a second one, with relaxed initialisation, when the first
  // registers fewer than `retry_below` of the images; a third, with the
  // defaults again, when both started a model that stopped short.
  int mapper_attempts = 3;
  double retry_below = 0.9;
  // Sequential matching only links frames near in time: a video that comes
  // back to a view it left (a second pass round the head) can break into
  // pieces. When the mapper still registers fewer than `retry_below` of the
  // images, every pair is matched (pairs already matched are kept) and the
  // mapper runs again, for at most this many images (0: never).
  int exhaustive_fallback_max = 300;
  // Frames only a few degrees apart (every frame of a walk round a head)
  // give the incremental mapper too little parallax between neighbours, and
  // it stops after a few images. When sequential matching registers too few
  // (before matching every pair), every `keyframe_step`-th image is mapped
  // alone, each matched with its next `overlap` keyframes, the images between
  // are registered into that model, and the whole is bundle adjusted; then
  // twice the step, while at least 16 keyframes remain. 0: never.
  int keyframe_step = 3;
  // A camera that comes back to views it saw before (round the head and on
  // past the start, or a second ring) drifts along the way, since sequential
  // matching never pairs the returning frames with the first. After a first
  // model, pairs of images that it shows looking at the same part of the
  // scene from directions within `revisit_angle_deg`, further apart in the
  // video than `overlap`, are matched too (at most `revisit_pairs` per image,
  // the closest in direction first), and the first model is refined with
  // them: its points triangulated again and the whole bundle adjusted, twice.
  // 0: off.
  double revisit_angle_deg = 25.0;
  int revisit_pairs = 8;
  // Fixed cameras: how far one camera's instants may lie apart in COLMAP's
  // model before the model counts as broken (degrees; fraction of the median
  // distance between the cameras).
  double max_instant_rotation_deg = 2.0;
  double max_instant_shift = 0.05;
  Status Check() const;
};

struct ColmapReport {
  int registered = 0, total = 0;
  double seconds = 0.0;
  int points = 0;
  double mean_reprojection_px = 0.0;
  std::string matcher, mask;
  // When sequential matching registered too few and keyframes were mapped
  // or every pair was matched after it: the images registered before that;
  // -1 otherwise.
  int sequential_registered = -1;
  // Keyframes mapped after it: every keyframe_step-th image, `keyframes` of
  // them (0: none); every pair matched after it.
  int keyframe_step = 0, keyframes = 0;
  bool exhaustive_fallback = false;
  // Pairs of revisited views matched after the first model (0: none found or off).
  int revisit_pairs = 0;
};

// Runs COLMAP in `work_dir` (kept: database, sparse/ and text model, logs) and
// fills `cameras` (frame "world", views of unused or unregistered frames marked
// unregistered).
Status RunColmap(const ColmapOptions& options, const IngestedCapture& capture, const fs::path& work_dir,
                 CameraSet* cameras, ColmapReport* report);

// Fixed cameras seen at several instants: each camera's registered instants
// must agree with its first (a camera that does not move cannot be in two
// places). Returns DataError naming the worst camera when one's instants lie
// more than `max_rotation_deg` or `max_shift` (times the rig's size, the
// median distance between the cameras' first poses) apart. A camera seen at
// one instant passes; with a single camera there is no size, and only the
// rotation is checked.
Status CheckFixedCameraInstants(const CameraSet& cameras, double max_rotation_deg, double max_shift);

// The parts of a COLMAP text model: cameras by id (pixel centres moved to
// integers), images by name with their camera id and cam_from_world, and the
// ids of the 3D points each image observes.
struct ColmapTextModel {
  std::map<int, CameraIntrinsics> cameras;
  std::map<std::string, std::pair<int, Eigen::Isometry3d>> images;
  std::map<std::string, std::vector<long>> observed;
};
Status ReadColmapCamerasAndImages(const fs::path& dir, ColmapTextModel* model);

// Pairs of images (by name) that a model shows revisiting a view: their
// optical axes within `max_angle_deg`, each seeing at least 15% of the
// points the other observes in front of it and inside its frame, and more than
// `min_index_gap` apart in `order` (every image given to COLMAP, in the
// sequential matcher's order; pairs nearer than that were matched
// sequentially). At most `per_image` partners per image, nearest in angle
// first; each pair appears once.
std::vector<std::pair<std::string, std::string>> FindRevisitPairs(const ColmapTextModel& model,
                                                                  const std::map<long, Eigen::Vector3d>& points,
                                                                  const std::vector<std::string>& order,
                                                                  double max_angle_deg, int min_index_gap,
                                                                  int per_image);
// points3D.txt of a text model: id -> position.
Status ReadColmapPoints(const fs::path& dir, std::map<long, Eigen::Vector3d>* points);

// Reads a COLMAP text model (cameras.txt, images.txt, points3D.txt). Image
// names "<camera>/<index>.png" map to views.
Status ReadColmapTextModel(const fs::path& dir, const IngestedCapture& capture, CameraSet* cameras,
                           ColmapReport* report);

}  // namespace headforge
