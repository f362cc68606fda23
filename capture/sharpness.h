// Blur detection by the variance of the Laplacian (Pech-Pacheco et al. 2000),
// judged against the sequence's own distribution rather than a fixed value,
// because the absolute figure depends on resolution, content and compression.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace headforge {

// Variance of the 3x3 Laplacian of the grey image (BGR or grey input).
double LaplacianVariance(const cv::Mat& image);

// For each value: true when it is below `ratio` times the median of `values`
// (ratio <= 0 keeps everything).
std::vector<bool> BlurredFrames(const std::vector<double>& sharpness, double ratio, double* median);

}  // namespace headforge
