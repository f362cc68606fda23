// Reading ingest's outputs back: the frames, masks and landmarks of each
// camera, as later stages (calibrate, align, track, train) see them.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "capture/landmarks.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct IngestedFrame {
  int index = 0;         // output frame index (frames/<camera>/<index>.png)
  int source_frame = 0;  // frame of the source video
  double time_s = 0.0;
  std::optional<Landmarks68> landmarks;  // in frame pixels; empty where the face was lost
  double score = 0.0;
};

struct IngestedCamera {
  std::string name;
  std::string source;
  int width = 0, height = 0;                // frame size
  int source_width = 0, source_height = 0;  // source image size
  bool fixed_crop = true;  // one crop for every frame (crop mode sequence or none)
  // The crop of the source into frames (fixed_crop): u_frame = (u_src + 0.5 - x0) * scale - 0.5.
  double crop_x0 = 0.0, crop_y0 = 0.0, crop_scale = 1.0;
  std::vector<IngestedFrame> frames;

  // The source image centre in frame pixels: the usual principal point guess.
  double SourceCentreX() const { return ((source_width - 1) / 2.0 + 0.5 - crop_x0) * crop_scale - 0.5; }
  double SourceCentreY() const { return ((source_height - 1) / 2.0 + 0.5 - crop_y0) * crop_scale - 0.5; }
};

struct IngestedCapture {
  fs::path workspace;
  double fps = 25.0;
  std::vector<IngestedCamera> cameras;

  fs::path FramePath(const std::string& camera, int index) const;
  fs::path MaskPath(const std::string& camera, int index) const;
  int num_frames() const { return cameras.empty() ? 0 : static_cast<int>(cameras[0].frames.size()); }
};

// Reads capture.json and landmarks.json of a workspace (as ingest wrote them).
Status ReadIngestedCapture(const fs::path& workspace, IngestedCapture* capture);

// "000042.png".
std::string FrameFileName(int index);

}  // namespace headforge
