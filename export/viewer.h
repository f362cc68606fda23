// viewer/index.html: one self-contained page (the engine and the avatars
// inlined; it opens offline, from disk) showing the mesh avatar playing its
// tracked animation beside the Gaussian avatar, drawn by PlayCanvas (which
// reads both glTF files, KHR_gaussian_splatting included), with an orbit
// camera: drag to turn, wheel to zoom. A baked clip (export --frames) plays
// in the Gaussian avatar's place, in time with the capture; ?clip=K in the
// page's address holds its K-th frame.
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct ViewerOptions {
  std::string playcanvas_js;  // PlayCanvas's UMD build (playcanvas.min.js), inlined
  fs::path mesh_glb;          // the mesh avatar ("" or missing: left out)
  fs::path gaussians_glb;     // the Gaussian avatar ("" or missing: left out)
  // The baked clip's frames as PlayCanvas's compressed PLY, in the order
  // played, with their times (seconds); shown instead of gaussians_glb.
  std::vector<fs::path> clip_files;
  std::vector<double> clip_times;
  int clip_frames = 0;        // of the whole clip (clip_files may hold its first ones only)
  double clip_fps = 25;
};

// Writes `out_dir`/index.html. NotFound when the engine's file is missing.
Status WriteViewer(const fs::path& out_dir, const ViewerOptions& options);

}  // namespace headforge
