#include "core/video_writer.h"

#include <opencv2/videoio.hpp>

namespace headforge {

VideoFileWriter::VideoFileWriter() = default;
VideoFileWriter::~VideoFileWriter() = default;
VideoFileWriter::VideoFileWriter(VideoFileWriter&&) noexcept = default;
VideoFileWriter& VideoFileWriter::operator=(VideoFileWriter&&) noexcept = default;

Status VideoFileWriter::Open(const fs::path& path, double fps, cv::Size size) {
  writer_ = std::make_unique<cv::VideoWriter>();
  path_ = path;
  size_ = size;
  for (const int codec : {cv::VideoWriter::fourcc('a', 'v', 'c', '1'), cv::VideoWriter::fourcc('m', 'p', '4', 'v')})
    if (writer_->open(path.string(), cv::CAP_FFMPEG, codec, fps, size)) return Status::Ok();
  writer_.reset();
  return Status::IoError("cannot open " + path.string() + " for writing a video (OpenCV's FFmpeg back end)");
}

bool VideoFileWriter::IsOpen() const { return writer_ && writer_->isOpened(); }

Status VideoFileWriter::Write(const cv::Mat& bgr) {
  if (!IsOpen()) return Status::Internal("video " + path_.string() + ": a frame written before Open");
  if (bgr.size() != size_ || bgr.type() != CV_8UC3)
    return Status::Internal("video " + path_.string() + ": a frame of another size or type than the video's");
  writer_->write(bgr);
  return Status::Ok();
}

Status VideoFileWriter::Close() {
  if (!writer_) return Status::Ok();
  writer_->release();
  writer_.reset();
  std::error_code ec;
  const auto bytes = fs::file_size(path_, ec);
  if (ec || bytes == 0)
    return Status::IoError("the video " + path_.string() + " was not written (a full disk? an encoder failure?)");
  return Status::Ok();
}

}  // namespace headforge
