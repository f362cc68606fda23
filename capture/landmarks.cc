#include "capture/landmarks.h"

#include <opencv2/imgproc.hpp>

#include <dlib/image_processing/shape_predictor.h>
#include <dlib/opencv.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/fs.h"

namespace headforge {

struct LandmarkPredictor::Impl {
  dlib::shape_predictor model;
};

LandmarkPredictor::LandmarkPredictor() : impl_(std::make_unique<Impl>()) {}
LandmarkPredictor::~LandmarkPredictor() = default;

Status LandmarkPredictor::Load(const std::string& path,
                               std::unique_ptr<LandmarkPredictor>* predictor) {
  Status readable = CheckReadableFile(path, "landmark model");
  if (!readable.ok())
    return Status(readable).WithContext(
        "the 68-point landmark model comes with Debian's libdlib-data (apt-get install "
        "libdlib-data) or set --landmark-model");
  std::unique_ptr<LandmarkPredictor> loaded(new LandmarkPredictor());
  try {
    dlib::deserialize(path) >> loaded->impl_->model;
  } catch (const std::exception& e) {
    return Status::DataError("cannot read the landmark model " + path +
                             " (is it the uncompressed shape_predictor_68_face_landmarks.dat?): " +
                             e.what());
  }
  if (loaded->impl_->model.num_parts() != 68)
    return Status::DataError("landmark model " + path + " predicts " +
                             std::to_string(loaded->impl_->model.num_parts()) +
                             " points, expected 68");
  *predictor = std::move(loaded);
  return Status::Ok();
}

namespace {

dlib::rectangle ToDlib(const cv::Rect2f& box) {
  return dlib::rectangle(std::lround(box.x), std::lround(box.y), std::lround(box.x + box.width),
                         std::lround(box.y + box.height));
}

Landmarks68 Run(const dlib::shape_predictor& model, const dlib::cv_image<dlib::bgr_pixel>& view,
                const cv::Rect2f& box) {
  const dlib::full_object_detection shape = model(view, ToDlib(box));
  Landmarks68 points;
  for (int i = 0; i < 68; ++i)
    points[i] = cv::Point2f(static_cast<float>(shape.part(i).x()), static_cast<float>(shape.part(i).y()));
  return points;
}

}  // namespace

Landmarks68 LandmarkPredictor::Predict(const cv::Mat& bgr, const cv::Rect2f& box) const {
  HF_CHECK(bgr.type() == CV_8UC3);
  // The box and half its size round it (where the predictor's features
  // reach), cut from the image and enlarged; pixel centres map as
  // x' = m (x - x0 + 0.5) - 0.5.
  const double m = magnification_;
  const cv::Rect region = cv::Rect(cvFloor(box.x - 0.5 * box.width), cvFloor(box.y - 0.5 * box.height),
                                   cvCeil(2 * box.width) + 1, cvCeil(2 * box.height) + 1) &
                          cv::Rect(0, 0, bgr.cols, bgr.rows);
  if (magnification_ == 1 || region.empty()) {
    dlib::cv_image<dlib::bgr_pixel> view(bgr);
    return Run(impl_->model, view, box);
  }
  cv::Mat large;
  cv::resize(bgr(region), large, cv::Size(), m, m, cv::INTER_LINEAR);
  const auto in = [&](double v, int origin) { return m * (v - origin + 0.5) - 0.5; };
  const auto out = [&](double v, int origin) { return float((v + 0.5) / m - 0.5 + origin); };
  const cv::Rect2f scaled(float(in(box.x, region.x)), float(in(box.y, region.y)), float(m * box.width),
                          float(m * box.height));
  dlib::cv_image<dlib::bgr_pixel> view(large);
  Landmarks68 points = Run(impl_->model, view, scaled);
  for (cv::Point2f& p : points) p = cv::Point2f(out(p.x, region.x), out(p.y, region.y));
  return points;
}

cv::Mat LandmarkHullMask(const Landmarks68& points, cv::Size size, double scale, double margin_px) {
  std::vector<cv::Point2f> scaled;
  for (const cv::Point2f& p : points)
    scaled.push_back(scale == 1.0 ? p : cv::Point2f(float((p.x + 0.5) * scale - 0.5), float((p.y + 0.5) * scale - 0.5)));
  std::vector<cv::Point2f> hull;
  cv::convexHull(scaled, hull);
  std::vector<cv::Point> outline;
  for (const cv::Point2f& p : hull) outline.emplace_back(cvRound(p.x), cvRound(p.y));
  cv::Mat mask(size, CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(mask, outline, cv::Scalar(255));
  const int r = std::max(0, int(std::lround(margin_px)));
  if (r > 0) cv::dilate(mask, mask, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  return mask;
}

cv::Rect2f LandmarkBounds(const Landmarks68& points) {
  float x0 = points[0].x, x1 = x0, y0 = points[0].y, y1 = y0;
  for (const auto& p : points) {
    x0 = std::min(x0, p.x);
    x1 = std::max(x1, p.x);
    y0 = std::min(y0, p.y);
    y1 = std::max(y1, p.y);
  }
  return cv::Rect2f(x0, y0, x1 - x0, y1 - y0);
}

bool PlausibleFaceLayout(const Landmarks68& p) {
  using namespace ibug;
  const float eyes_y = 0.25f * (p[kRightEyeOuter].y + p[kRightEyeInner].y + p[kLeftEyeInner].y +
                                p[kLeftEyeOuter].y);
  const float mouth_y = 0.5f * (p[kMouthRight].y + p[kMouthLeft].y);
  return eyes_y < p[kNoseTip].y && p[kNoseTip].y < mouth_y && mouth_y < p[kChin].y &&
         p[kRightEyeOuter].x < p[kLeftEyeOuter].x && p[kMouthRight].x < p[kMouthLeft].x;
}

}  // namespace headforge
