// The ingest stage: turns one video or image folder per camera into the
// workspace's frames/, masks/, landmarks.json and capture.json (DESIGN.md).
//
// Frames are sampled in time, blurred ones dropped, the face detected and its
// 68 landmarks predicted, each frame cropped around the head and resized, and a
// head mask made (or the user's masks cropped alike). Several cameras are
// synchronised by frame index, shifted by per-camera offsets.
#pragma once

#include <string>
#include <vector>

#include "capture/face_detector.h"
#include "capture/face_mask.h"
#include "capture/matte.h"
#include "core/fs.h"
#include "core/hash.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct IngestOptions {
  // One video file or image folder per camera.
  std::vector<std::string> inputs;
  // Frames per second to sample; 0 keeps every source frame.
  double fps = 0.0;
  // Upper bound on the number of sampled frames (the first ones); 0 for no bound.
  int max_frames = 0;
  // Keep at most this many frames, chosen from all the sampled ones for
  // their coverage of head poses and expressions (the sharpest of alike
  // ones): a long recording's frame budget. 0 keeps every frame. The
  // default is the draft preset's budget; `headforge run` gives the chosen
  // training preset's when it is not set.
  int select = 300;
  // Time range to sample, in seconds from the start; end 0 means to the end.
  double start = 0.0;
  double end = 0.0;
  // Side of the square output frames (pixels).
  int resolution = 512;
  // "sequence": one square crop per camera holding the head in every frame
  // (fixed intrinsics); "frame": a square of fixed size following the head;
  // "none": the whole frame, longer side scaled to `resolution`; "auto":
  // none for several cameras or one whose background moves (structure from
  // motion needs the background), else sequence.
  std::string crop = "auto";
  // Side of a crop as a multiple of the face size (landmark extent).
  double crop_scale = 2.0;
  // A frame is dropped as blurred when its Laplacian variance is below this
  // fraction of the camera's median; 0 keeps every frame.
  double blur_ratio = 0.35;
  FaceDetectorOptions detector;
  // dlib 68-point shape predictor file.
  std::string landmark_model;
  // The predictor reads each face's region enlarged this many times
  // (LandmarkPredictor::set_magnification): 1 gives whole-pixel points.
  int landmark_magnification = 1;
  // A folder of the user's own masks (one image per source frame, sorted by
  // name; a sub-folder per camera name when there are several cameras).
  std::string masks;
  // The mask of each frame: auto (MediaPipe's selfie segmentation, or GrabCut
  // where the models are not installed), selfie, meet, rvm or grabcut.
  std::string matte = "auto";
  // Folder of the learned models (default: DefaultVisionModelsDir()).
  std::string vision_models;
  // MediaPipe's face mesh (468 points) beside the 68 in landmarks.json:
  // "auto" where the model is installed, "on" (an error without it), "off".
  std::string face_mesh = "auto";
  // Below this face probability a frame's mesh is left out.
  double mesh_min_score = 0.5;
  HeadMaskOptions mask;
  // Per-camera offset in source frames: camera i's frame (j + offsets[i])
  // pairs with the first camera's frame j. Empty: all zero.
  std::vector<int> offsets;
  // Frame rate assumed for image folders.
  double folder_fps = 25.0;
  // Warn when the face is found in fewer than this fraction of a camera's frames.
  double min_face_fraction = 0.5;
  // Refuse a camera whose face, where found, spans fewer source pixels than
  // this (the 68 landmarks' extent, median over the frames): too small to
  // track, and to build an avatar from. 0: no limit.
  double min_face_px = 40;
  // Seed of the mask segmentation's random initialisation.
  int seed = 0;

  Status Check() const;
  MatteOptions Matte() const;
};

// Binds every field to its "ingest.*" key; `data_dir` fills the model defaults.
void AddIngestOptions(OptionSet* options, IngestOptions* ingest);
// Applies the shared data folder to options whose defaults live there.
void ResolveIngestDefaults(const std::string& data_dir, IngestOptions* ingest);

// What decides ingest's outputs besides its options (and the stage's
// version): the contents of every input and mask, and the model files' stamps.
Status AddIngestInputs(const IngestOptions& options, Hasher* hasher);

struct IngestSummary {
  int sampled = 0;           // synchronised frames sampled
  int kept = 0;              // frames written
  int dropped_blur = 0;      // dropped as blurred
  int dropped_missing = 0;   // dropped because a camera had no such frame
  int dropped_unselected = 0;  // left out by --select
  int face_lost = 0;         // kept frames (over all cameras) without a detected face
  int with_landmarks = 0;    // kept frames (over all cameras) with landmarks
  int with_mesh = 0;         // ... and with the face mesh
  int cameras = 0;
  std::string crop;          // the crop used ("auto" resolved)
  std::string masks;         // what made the masks: selfie, meet, rvm, grabcut or user
  // One line per input video ffmpeg's decoder found damaged or truncated.
  std::vector<std::string> damaged;
  // One line per camera where several faces were seen: which one is followed.
  std::vector<std::string> faces;
  std::string OneLine() const;
};

// Runs ingest, writing frames/, masks/, landmarks.json and capture.json under
// `out_dir`. Expected failures (unreadable input, no face, empty range) come
// back as a Status that names the file and suggests what to try.
Status RunIngest(const IngestOptions& options, const fs::path& out_dir, int threads,
                 Progress* progress, IngestSummary* summary);

}  // namespace headforge
