// Ingest's outputs, capture.json and landmarks.json, as one typed record: the
// frames, masks and landmarks of each camera as later stages (calibrate,
// align, track, train) see them, and what ingest dropped and why.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "capture/crop.h"
#include "capture/landmarks.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct IngestedFrame {
  int index = 0;         // output frame index (frames/<camera>/<index>.png)
  int source_frame = 0;  // frame of the source video
  double time_s = 0.0;
  std::optional<Landmarks68> landmarks;  // in frame pixels; empty where the face was lost
  double score = 0.0;                    // the detector's confidence
  std::string detector;                  // which detector found the face
  cv::Rect2f box;                        // the face box, frame pixels
  double sharpness = 0.0;                // variance of the Laplacian
  std::string source_file;               // image folders: the file it came from
  std::optional<CropWindow> crop;        // crop mode "frame": this frame's own crop
  // MediaPipe's face mesh (vision/face_mesh.h) where it found the face: 468
  // points, x and y in frame pixels, z a relative depth in frame pixels
  // (nearer is smaller); empty where it was not run or lost the face, the
  // 68 points then standing alone.
  std::vector<cv::Point3f> mesh;
  float mesh_score = 0.0f;               // the network's face probability
};

struct IngestedCamera {
  std::string name;
  std::string source;
  double source_fps = 0.0;
  int offset = 0;                           // source frames, for synchronisation
  double median_sharpness = 0.0;
  // ffmpeg's decoder errors in the source video (CheckVideoStream): damaged
  // or truncated data, where frames may be missing or garbled.
  int decoder_errors = 0;
  std::string decoder_error;                // the first
  std::string masks = "grabcut";            // what made them: selfie, meet, rvm, grabcut or user
  int width = 0, height = 0;                // frame size
  int source_width = 0, source_height = 0;  // source image size
  bool fixed_crop = true;  // one crop for every frame (crop mode sequence or none)
  // The crop of the source into frames (fixed_crop): u_frame = (u_src + 0.5 - x0) * scale - 0.5,
  // over crop_width x crop_height source pixels.
  double crop_x0 = 0.0, crop_y0 = 0.0, crop_scale = 1.0;
  double crop_width = 0.0, crop_height = 0.0;
  std::vector<IngestedFrame> frames;

  // The source image centre in frame pixels: the usual principal point guess.
  double SourceCentreX() const { return ((source_width - 1) / 2.0 + 0.5 - crop_x0) * crop_scale - 0.5; }
  double SourceCentreY() const { return ((source_height - 1) / 2.0 + 0.5 - crop_y0) * crop_scale - 0.5; }
};

// A sampled instant that was not kept.
struct DroppedSample {
  int sample = 0;
  std::map<std::string, int64_t> source_frames;  // camera -> its source frame
  std::string reason;                            // blur, missing or unselected
  std::string detail;
};

// The counts of ingest's report.
struct IngestCounts {
  int sampled = 0, kept = 0, dropped_blur = 0, dropped_missing = 0, face_lost = 0, with_landmarks = 0;
};

struct IngestedCapture {
  static constexpr int kVersion = 2;  // of capture.json and landmarks.json; the reader refuses another

  fs::path workspace;
  double fps = 25.0;
  int resolution = 0;         // --frame-size
  std::string crop_mode;      // sequence, frame or none
  std::vector<int> samples;   // per output frame: the sample it came from
  std::vector<IngestedCamera> cameras;
  std::vector<DroppedSample> dropped;
  IngestCounts counts;

  fs::path FramePath(const std::string& camera, int index) const;
  fs::path MaskPath(const std::string& camera, int index) const;
  // nullptr when the capture has no such camera, or the camera no such frame.
  const IngestedCamera* FindCamera(const std::string& name) const;
  const IngestedFrame* FindFrame(const std::string& camera, int index) const;
  int num_frames() const { return cameras.empty() ? 0 : static_cast<int>(cameras[0].frames.size()); }
};

// Writes capture.json and landmarks.json into `dir`.
Status WriteIngestedCapture(const IngestedCapture& capture, const fs::path& dir);
// Reads capture.json and landmarks.json of a workspace (as ingest wrote them),
// checking their version.
Status ReadIngestedCapture(const fs::path& workspace, IngestedCapture* capture);

// "000042.png".
std::string FrameFileName(int index);

}  // namespace headforge
