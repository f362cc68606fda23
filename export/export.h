// The export stage: a trained workspace in the formats other tools open.
//   export/avatar_mesh.glb         the mesh avatar (glTF: morph targets, the tracked animation, a baked texture)
//   export/gaussians.ply           the Gaussians of one pose (3D Gaussian Splatting's PLY)
//   export/gaussians.glb           the same as glTF with KHR_gaussian_splatting
//   export/clip/                   a baked clip: the Gaussians of each of --frames, one SPZ file a frame
//   export/weights/                weights.safetensors + config.json
//   export/videos/                 self-reenactment (render | frame | error), orbit, cross-reenactment
//   export/viewer/index.html       the avatars in a page that opens offline (PlayCanvas)
//   export/face_metrics.json       the held-out renders' identity similarity (CSIM) and landmark distance (F-LMD)
//   export/report.html             one self-contained page about the run
//   export/export.json             what was written, and the options
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/hash.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct ExportOptions {
  std::vector<std::string> formats = {"mesh", "gaussians", "weights", "videos", "viewer", "report"};
  int splat_frame = -1;      // the frame whose Gaussians are written (-1: neutral expression, frame 0's pose)
  // A baked clip of the Gaussian avatar (export/splat_clip.h): the frames
  // as ParseFrameList reads them ("all", "0-49", "0-124:5", ...); empty: none.
  std::vector<std::string> frames;
  std::string clip_format = "spz";  // spz, compressed.ply or ply
  std::string splat_transform = kDefaultSplatTransform;
  int texture_size = 512;    // the mesh avatar's texture: texels per side of the skin's square
  int bake_views = 24;       // views baked into it
  // The orbit video swings the camera this far each way; 180 turns it all
  // the way round; 0: 45 for a capture from one side, 180 for one whose
  // cameras go more than half way round the head.
  double orbit_deg = 0;
  // The Gaussian blendshapes refined through the rasterizer against the
  // training frames after their fit to the networks (blendshapes.h):
  // steps, and minutes at most (0: no limit); 0 steps: the fit alone. 300:
  // on GRID swiz3n's draft avatar the views set aside gain 1.4 dB by then
  // and 1.7 dB by step 1 000, the held-out frames 0.35 dB either way.
  double blendshape_prune = 0.5;
  int blendshape_refine_steps = 300;
  double blendshape_refine_minutes = 0;
  std::string drive;         // a tracked workspace whose expressions drive a cross-reenactment video
  std::string drive_remedy = "none";  // what is done to its weights: none, relative, relative+span (avatar_render.h)
  // Which trained model the Gaussians, weights and videos come from:
  // gaussian-style, gan-avatar, or auto (gaussian-style when it is trained,
  // else gan-avatar).
  std::string model = "auto";
  std::string device = "cpu";
  std::string chart_js = kDefaultChartJs;            // inlined into report.html
  std::string playcanvas_js = kDefaultPlayCanvasJs;  // inlined into viewer/index.html
  std::string tfjs_js = kDefaultTfjs;                // inlined into drive/index.html
  std::string vision_models;                         // the face mesh's folder ("": DefaultVisionModelsDir())
  // node_modules holding @vladmandic/face-api, whose recognition network's
  // weights give the identity score the report shows beside the landmark
  // distance (avatar/face_metrics.h); empty: neither is scored. The faces
  // are found with ingest's detector and landmark model (set by the export
  // stage from the data folder).
  std::string face_api = kDefaultFaceApi;
  // results.json files of `headforge bench calibrate` and `bench track`
  // shown in the report; empty: the workspace's bench_calibrate/ and
  // bench_track/ ones, where they exist (BenchResultFiles).
  std::vector<std::string> bench_results;
  std::string ultraface_dir, landmark_model;

  static const char* const kDefaultChartJs;
  static const char* const kDefaultPlayCanvasJs;
  static const char* const kDefaultFaceApi;
  static const char* const kDefaultSplatTransform;
  static const char* const kDefaultTfjs;
  Status Check() const;
};

void AddExportOptions(OptionSet* options, ExportOptions* exported);

// The bench results the report of `workspace` shows (ExportOptions::bench_results).
std::vector<fs::path> BenchResultFiles(const ExportOptions& options, const fs::path& workspace);

struct ExportSummary {
  std::vector<std::string> files;  // relative to the output folder
  double seconds = 0;
  std::string OneLine() const;
};

// Whether the formats asked for need a trained model (Gaussians, weights,
// videos, a baked clip) or only the tracking (mesh, viewer, report).
bool ExportNeedsModel(const ExportOptions& options);

// What an export inlines besides the workspace's files, for its fingerprint:
// the drive page's scripts built into this program, the npm files
// (Chart.js, PlayCanvas, TensorFlow.js) and the face mesh model, so that
// an upgrade of either makes the export run again.
Status AddExportAssets(const ExportOptions& options, Hasher* hasher);

// Writes into `out_dir` what options.formats asks for from `workspace`
// (tracked; trained for the Gaussians, weights and videos).
Status RunExport(const ExportOptions& options, const fs::path& workspace, const std::string& face_model,
                 const fs::path& out_dir, Progress* progress, ExportSummary* summary);

}  // namespace headforge
