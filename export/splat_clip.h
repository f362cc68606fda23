// A baked clip: the trained Gaussian avatar posed at a list of frames, one
// compact splat file a frame, for players that show Gaussians but cannot run
// the avatar's networks.
//   clip/frame_000042.spz   the frame's Gaussians (SPZ, through @playcanvas/splat-transform;
//                           or .compressed.ply, or 3D Gaussian Splatting's .ply)
//   clip/clip.json          the frames, their times in the capture, the format
// The Gaussians are in the avatar's head frame (metres, +y up, the face
// toward +z), colour as the degree-0 coefficient; every frame has the same
// Gaussians in the same order.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "avatar/avatar_export.h"
#include "core/fs.h"
#include "core/progress.h"
#include "core/status.h"
#include "export/gaussian_ply.h"

namespace headforge {

// The splats as 3D Gaussian Splatting's PLY stores them: log scales, logit
// opacity, colour as the degree-0 coefficient.
GaussianCloud CloudFromSplats(const AvatarSplats& splats);

// InvalidArgument unless `format` is spz, compressed.ply or ply.
Status CheckClipFormat(const std::string& format);

struct SplatClipOptions {
  std::vector<int> frames;         // in the order played
  std::string format = "spz";      // spz, compressed.ply or ply
  std::string splat_transform;     // the splat-transform command (for spz, compressed.ply and the viewer's copies)
  // Not empty: each frame also as PlayCanvas's compressed PLY in this folder,
  // for the viewer page to inline, until they would pass viewer_bytes.
  fs::path viewer_dir;
  int64_t viewer_bytes = int64_t(64) << 20;

  Status Check() const;
};

struct SplatClip {
  std::vector<std::string> files;          // relative to the export folder (clip/...)
  std::vector<int> frames;                 // as played
  std::vector<double> times;               // seconds from the capture's first frame
  std::vector<fs::path> viewer_files;      // the viewer's copies, the clip's first frames
  int gaussians = 0;
  double fps = 0;                          // the capture's
};

// Poses the avatar trained in `model_dir` at each frame and writes
// `out_dir`/clip/. NotFound (saying how to install it) when the format
// needs splat-transform and it cannot be run.
Status WriteSplatClip(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                      const SplatClipOptions& options, const fs::path& out_dir, Progress* progress, SplatClip* clip);

}  // namespace headforge
