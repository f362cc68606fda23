#include "core/image_io.h"

#include <opencv2/imgcodecs.hpp>
#include <vector>

namespace headforge {

Status WriteImageAtomic(const fs::path& path, const cv::Mat& image) {
  std::vector<uchar> buffer;
  std::vector<int> params;
  const std::string ext = path.extension().string();
  if (ext == ".png") params = {cv::IMWRITE_PNG_COMPRESSION, 3};
  if (ext == ".jpg" || ext == ".jpeg") params = {cv::IMWRITE_JPEG_QUALITY, 95};
  try {
    if (!cv::imencode(ext, image, buffer, params))
      return Status::Internal("cannot encode image " + path.string());
  } catch (const cv::Exception& e) {
    return Status::Internal("cannot encode image " + path.string() + ": " + e.what());
  }
  return WriteFileAtomic(path, std::string(buffer.begin(), buffer.end()));
}

Status ReadImage(const fs::path& path, cv::Mat* image, int flags) {
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "image"));
  *image = cv::imread(path.string(), flags);
  if (image->empty()) return Status::DataError("cannot decode image " + path.string());
  return Status::Ok();
}

}  // namespace headforge
