// Image files of the workspace: 8-bit sRGB PNGs written atomically.
#pragma once

#include <opencv2/core.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// Encodes by the extension of `path` (.png, .jpg) and writes through a temporary file.
Status WriteImageAtomic(const fs::path& path, const cv::Mat& image);
// Reads an image as 8-bit BGR (flags as cv::imread); DataError if it cannot be decoded.
Status ReadImage(const fs::path& path, cv::Mat* image, int flags = 1 /*cv::IMREAD_COLOR*/);

}  // namespace headforge
