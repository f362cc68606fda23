// viewer/index.html: one self-contained page (the engine and the avatars
// inlined; it opens offline, from disk) showing the mesh avatar playing its
// tracked animation beside the Gaussian avatar, drawn by PlayCanvas (which
// reads both glTF files, KHR_gaussian_splatting included), with an orbit
// camera: drag to turn, wheel to zoom.
#pragma once

#include <string>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct ViewerOptions {
  std::string playcanvas_js;  // PlayCanvas's UMD build (playcanvas.min.js), inlined
  fs::path mesh_glb;          // the mesh avatar ("" or missing: left out)
  fs::path gaussians_glb;     // the Gaussian avatar ("" or missing: left out)
};

// Writes `out_dir`/index.html. NotFound when the engine's file is missing.
Status WriteViewer(const fs::path& out_dir, const ViewerOptions& options);

}  // namespace headforge
