// Rendering a trained avatar for callers that do not use LibTorch: any frame
// of its workspace (or of another workspace's tracking, which then drives
// it), from the frame's camera turned round the head.
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct AvatarRenderOptions {
  std::string drive;            // a workspace whose tracked expressions drive the avatar ("": its own)
  std::vector<int> frames;      // frames to render (of `drive` when given); empty: all
  double yaw_deg = 0;           // the camera moved round the head, toward the subject's left
  double pitch_deg = 0;         // ... and up
  int resolution = 0;           // the longer side in pixels (0: as trained)
  std::string device = "cpu";
  bool video = false;           // one render.mp4 instead of a PNG per frame
  bool side_by_side = false;    // the frame beside its render (own frames only)
  double background = 1.0;      // grey level behind the head
};

struct AvatarRenderSummary {
  int frames = 0;
  double seconds_per_frame = 0;  // pose and render, without reading or writing
  std::vector<std::string> files;
};

// Renders the avatar trained in `workspace` (models/gaussian_style) into `out_dir`.
Status RenderAvatarFrames(const fs::path& workspace, const std::string& face_model, const AvatarRenderOptions& options,
                          const fs::path& out_dir, Progress* progress, AvatarRenderSummary* summary);

}  // namespace headforge
