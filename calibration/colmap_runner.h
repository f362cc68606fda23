// Structure from motion with the real `colmap` executable, run headless with
// CPU SIFT on the ingested frames: feature extraction with one shared camera
// per video, sequential (one video) or exhaustive (several) matching, the
// incremental mapper; the largest model is converted to text and read back.
#pragma once

#include <map>
#include <string>
#include <utility>

#include "calibration/camera_set.h"
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
  // registers fewer than `retry_below` of the images.
  int mapper_attempts = 2;
  double retry_below = 0.9;
  // Sequential matching only links frames near in time: a video that comes
  // back to a view it left (a second pass round the head) can break into
  // pieces. When the mapper still registers fewer than `retry_below` of the
  // images, every pair is matched (pairs already matched are kept) and the
  // mapper runs again, for at most this many images (0: never).
  int exhaustive_fallback_max = 300;
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
  // When sequential matching registered too few and every pair was matched
  // after it: the images registered before that; -1 otherwise.
  int sequential_registered = -1;
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
// integers), and images by name with their camera id and cam_from_world.
struct ColmapTextModel {
  std::map<int, CameraIntrinsics> cameras;
  std::map<std::string, std::pair<int, Eigen::Isometry3d>> images;
};
Status ReadColmapCamerasAndImages(const fs::path& dir, ColmapTextModel* model);

// Reads a COLMAP text model (cameras.txt, images.txt, points3D.txt). Image
// names "<camera>/<index>.png" map to views.
Status ReadColmapTextModel(const fs::path& dir, const IngestedCapture& capture, CameraSet* cameras,
                           ColmapReport* report);

}  // namespace headforge
