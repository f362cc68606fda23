// Face detection: UltraFace (ONNX, run by OpenCV's dnn module) by default,
// dlib's HOG detector as the fallback when UltraFace finds nothing or its model
// cannot be loaded. One detector per thread: neither backend is thread-safe.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/status.h"

namespace headforge {

struct FaceDetectorOptions {
  // "ultraface" (RFB-320, fast), "ultraface-640" (RFB-640, small faces) or
  // "dlib-hog" (CPU HOG + linear SVM, frontal faces only).
  std::string detector = "ultraface";
  // Folder holding version-RFB-320.onnx and version-RFB-640.onnx.
  std::string ultraface_dir;
  // Minimum UltraFace face probability in [0, 1].
  double score_threshold = 0.7;
  // Try dlib's HOG detector on frames where the main detector finds nothing.
  bool hog_fallback = true;
  // Frame the landmark model's box with dlib's HOG detector around each
  // UltraFace face where it fires and the head is turned (the framing the
  // landmark model was trained with); elsewhere a fixed conversion of the
  // UltraFace box.
  bool hog_framing = true;

  Status Check() const;
  // The ONNX file the options select ("" for dlib-hog).
  std::string UltraFaceModelPath() const;
};

struct FaceDetection {
  cv::Rect2f box;      // the detector's own box, pixels of the input image
  // The box in the framing dlib's landmark model was trained with (its HOG
  // detector's): square, from the brows to about the chin.
  cv::Rect2f landmark_box;
  float score = 0.0f;  // detector confidence; HOG scores are mapped into (0, 1)
  bool from_fallback = false;
};

class FaceDetector {
 public:
  virtual ~FaceDetector() = default;
  static Status Create(const FaceDetectorOptions& options, std::unique_ptr<FaceDetector>* detector);
  // Faces in a BGR image, most confident first.
  virtual std::vector<FaceDetection> Detect(const cv::Mat& bgr) = 0;
};

}  // namespace headforge
