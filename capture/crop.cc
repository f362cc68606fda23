#include "capture/crop.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace headforge {

cv::Point2f CropWindow::Map(const cv::Point2f& p) const {
  return cv::Point2f(static_cast<float>((p.x + 0.5 - x0) * scale - 0.5),
                     static_cast<float>((p.y + 0.5 - y0) * scale - 0.5));
}

cv::Mat CropWindow::Apply(const cv::Mat& source, int interpolation, int border) const {
  // Shrinking first by area averaging avoids aliasing that warpAffine's
  // interpolation alone would leave when the scale is well below one.
  cv::Mat input = source;
  double sx = 1.0, sy = 1.0;
  if (scale < 0.75 && interpolation != cv::INTER_NEAREST) {
    const cv::Size shrunk(std::max(1, static_cast<int>(std::lround(source.cols * scale))),
                          std::max(1, static_cast<int>(std::lround(source.rows * scale))));
    cv::resize(source, input, shrunk, 0, 0, cv::INTER_AREA);
    sx = static_cast<double>(shrunk.width) / source.cols;
    sy = static_cast<double>(shrunk.height) / source.rows;
  }
  // Output centre coordinates from the (possibly shrunk) input's:
  // u_out = (u_in + 0.5) * scale / sx - x0 * scale - 0.5.
  const double ax = scale / sx, ay = scale / sy;
  cv::Mat m = (cv::Mat_<double>(2, 3) << ax, 0.0, 0.5 * ax - x0 * scale - 0.5, 0.0, ay,
               0.5 * ay - y0 * scale - 0.5);
  cv::Mat out;
  cv::warpAffine(input, out, m, output, interpolation, border, cv::Scalar::all(0));
  return out;
}

bool CropWindow::Exceeds(cv::Size size) const {
  return x0 < 0 || y0 < 0 || x0 + width > size.width || y0 + height > size.height;
}

CropWindow SquareCrop(const cv::Point2d& centre, double side, int resolution) {
  CropWindow crop;
  crop.x0 = centre.x + 0.5 - side / 2.0;  // centre.x is a pixel centre; +0.5 to edges
  crop.y0 = centre.y + 0.5 - side / 2.0;
  crop.width = crop.height = side;
  crop.scale = resolution / side;
  crop.output = cv::Size(resolution, resolution);
  return crop;
}

CropWindow FullFrameCrop(cv::Size source, int resolution) {
  CropWindow crop;
  crop.width = source.width;
  crop.height = source.height;
  crop.scale = static_cast<double>(resolution) / std::max(source.width, source.height);
  crop.output = cv::Size(std::max(1, static_cast<int>(std::lround(source.width * crop.scale))),
                         std::max(1, static_cast<int>(std::lround(source.height * crop.scale))));
  return crop;
}

FaceFrame FaceFrameOf(const Landmarks68& landmarks) {
  const cv::Rect2f b = LandmarkBounds(landmarks);
  FaceFrame face;
  face.centre = cv::Point2d(b.x + 0.5 * b.width, b.y + 0.5 * b.height);
  face.size = std::max(b.width, b.height);
  return face;
}

namespace {
double MedianSize(const std::vector<FaceFrame>& faces) {
  std::vector<double> sizes;
  for (const auto& f : faces) sizes.push_back(f.size);
  std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
  return sizes[sizes.size() / 2];
}
}  // namespace

CropWindow SequenceCrop(const std::vector<FaceFrame>& faces, double crop_scale, int resolution) {
  const double side = crop_scale * MedianSize(faces);
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const auto& f : faces) {
    x0 = std::min(x0, f.centre.x - side / 2);
    x1 = std::max(x1, f.centre.x + side / 2);
    y0 = std::min(y0, f.centre.y - side / 2);
    y1 = std::max(y1, f.centre.y + side / 2);
  }
  return SquareCrop(cv::Point2d(0.5 * (x0 + x1), 0.5 * (y0 + y1)), std::max(x1 - x0, y1 - y0),
                    resolution);
}

std::vector<CropWindow> FollowingCrops(const std::vector<FaceFrame>& faces, double crop_scale,
                                       int resolution, int radius) {
  const double side = crop_scale * MedianSize(faces);
  std::vector<CropWindow> crops;
  const int n = static_cast<int>(faces.size());
  for (int i = 0; i < n; ++i) {
    cv::Point2d sum(0, 0);
    int count = 0;
    for (int j = std::max(0, i - radius); j <= std::min(n - 1, i + radius); ++j, ++count)
      sum += faces[j].centre;
    crops.push_back(SquareCrop(sum / count, side, resolution));
  }
  return crops;
}

}  // namespace headforge
