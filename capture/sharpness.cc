#include "capture/sharpness.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace headforge {

double LaplacianVariance(const cv::Mat& image) {
  cv::Mat grey = image;
  if (image.channels() == 3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  cv::Mat laplacian;
  cv::Laplacian(grey, laplacian, CV_64F, 1);
  cv::Scalar mean, stddev;
  cv::meanStdDev(laplacian, mean, stddev);
  return stddev[0] * stddev[0];
}

std::vector<bool> BlurredFrames(const std::vector<double>& sharpness, double ratio, double* median) {
  std::vector<bool> blurred(sharpness.size(), false);
  *median = 0.0;
  if (sharpness.empty()) return blurred;
  std::vector<double> sorted = sharpness;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  *median = sorted[sorted.size() / 2];
  if (ratio <= 0.0) return blurred;
  for (size_t i = 0; i < sharpness.size(); ++i) blurred[i] = sharpness[i] < ratio * *median;
  return blurred;
}

}  // namespace headforge
