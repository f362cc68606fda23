// The 68 iBUG facial landmarks, predicted by dlib's regression-tree shape
// predictor (Kazemi & Sullivan 2014) from Debian's libdlib-data. That model was
// trained on iBUG 300-W, whose licence excludes commercial use.
#pragma once

#include <array>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "core/status.h"

namespace headforge {

using Landmarks68 = std::array<cv::Point2f, 68>;

// iBUG 68 indices used across the tool.
namespace ibug {
constexpr int kJawFirst = 0, kJawLast = 16, kChin = 8;
constexpr int kRightEyeOuter = 36, kRightEyeInner = 39;  // subject's right, image left
constexpr int kLeftEyeInner = 42, kLeftEyeOuter = 45;
constexpr int kNoseTip = 30;
constexpr int kMouthRight = 48, kMouthLeft = 54;
constexpr int kBrowFirst = 17, kBrowLast = 26;
}  // namespace ibug

class LandmarkPredictor {
 public:
  // Loads the model (about 100 MB; a second or so). Thread-safe once loaded.
  static Status Load(const std::string& path, std::unique_ptr<LandmarkPredictor>* predictor);
  ~LandmarkPredictor();

  // Landmarks of the face in `box` of a BGR image; `box` must be in the framing
  // of dlib's HOG detector (FaceDetection::landmark_box).
  Landmarks68 Predict(const cv::Mat& bgr, const cv::Rect2f& box) const;

  // dlib gives each point as a whole pixel of the image it reads: on a small
  // face (a GRID clip's eyes are some 60 px apart) that rounding is a
  // noise of 0.29 px (its standard deviation) on every coordinate. With a
  // magnification m > 1 the predictor reads the face's region enlarged m
  // times (bilinear), so its points fall on 1/m of a pixel. 1: the image
  // as it is.
  void set_magnification(int m) { magnification_ = m < 1 ? 1 : m; }
  int magnification() const { return magnification_; }

 private:
  LandmarkPredictor();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int magnification_ = 1;
};

// The tight box around a set of landmarks.
cv::Rect2f LandmarkBounds(const Landmarks68& points);
// The landmarks' convex hull filled (255) in a mask of `size`, the points
// first taken to an image `scale` times the size (pixel centres at
// integers), then grown by `margin_px`.
cv::Mat LandmarkHullMask(const Landmarks68& points, cv::Size size, double scale = 1.0, double margin_px = 0.0);
// True when the landmarks have a face's layout: eyes above the mouth, the
// subject's right eye left of the left eye, nose between eyes and mouth.
bool PlausibleFaceLayout(const Landmarks68& points);

}  // namespace headforge
