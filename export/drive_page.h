// drive/index.html: the Gaussian avatar's blendshapes (export --formats
// blendshapes) in a self-contained page that poses them every frame from a
// recorded take (the capture's own tracking, a Live Link Face CSV, a
// tracking.json) or live from the webcam: MediaPipe's face mesh run in the
// page by TensorFlow.js, and the 53 expression weights and the head pose
// solved against where the face model puts the mesh's 468 points. The page
// draws the Gaussians itself (WebGL 2), as the CPU rasterizer does.
#pragma once

#include <string>

#include "core/fs.h"
#include "core/hash.h"
#include "core/status.h"

namespace headforge {

struct DrivePageOptions {
  fs::path workspace;          // tracked: tracking.json, cameras_head.json
  std::string face_model;      // the face model file the tracking used
  fs::path blendshapes_dir;    // export's blendshapes/ (blendshapes.json, blendshapes.bin)
  std::string mesh_embedding;  // where the 468 points sit on the model ("": the shipped one)
  // TensorFlow.js's browser build and the folder of facemesh.json/.bin; the
  // page drives from the webcam only when both are there.
  std::string tfjs_js;
  fs::path vision_models;
  // The mesh avatar (export's avatar_mesh.glb) and PlayCanvas's UMD build:
  // where both are there, the page draws the mesh beside the Gaussians, its
  // morph targets posed by the same weights.
  fs::path mesh_glb;
  std::string playcanvas_js;
  bool half_offsets = true;    // the offsets as float16 (half the page; no visible change)
};

struct DrivePageSummary {
  bool webcam = false;  // the page holds the face mesh model
  bool mesh = false;    // the page draws the mesh avatar too
  int64_t gaussians = 0;
  int64_t page_bytes = 0;
  std::string note;     // why the webcam is off, when it is
};

// Writes `out_dir`/index.html and `out_dir`/face_basis.json (the face mesh's
// points as linear functions of the expression weights for the tracked
// subject, and the capture's camera: what the page solves against).
Status WriteDrivePage(const fs::path& out_dir, const DrivePageOptions& options, DrivePageSummary* summary);

// The page's own scripts, built into this program: what a page written by
// another version may differ by (the export's fingerprint takes them).
void AddDrivePageScripts(Hasher* hasher);

}  // namespace headforge
