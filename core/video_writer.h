// An MP4 video written frame by frame through OpenCV's FFmpeg back end:
// H.264, which browsers play (the report and the viewer embed the videos),
// or MPEG-4 part 2 where the FFmpeg build has no H.264 encoder. Used by the
// track stage's overlay and by render and export's avatar videos.
#pragma once

#include <opencv2/core.hpp>

#include <memory>

#include "core/fs.h"
#include "core/status.h"

namespace cv {
class VideoWriter;
}

namespace headforge {

class VideoFileWriter {
 public:
  VideoFileWriter();
  ~VideoFileWriter();
  VideoFileWriter(VideoFileWriter&&) noexcept;
  VideoFileWriter& operator=(VideoFileWriter&&) noexcept;

  // Opens `path` for frames of `size` at `fps`.
  Status Open(const fs::path& path, double fps, cv::Size size);
  bool IsOpen() const;
  // An 8-bit BGR frame of the size given to Open.
  Status Write(const cv::Mat& bgr);
  // Finishes the file; an empty file (a full disk, a failed encoder) is an
  // error that names it.
  Status Close();

 private:
  std::unique_ptr<cv::VideoWriter> writer_;
  fs::path path_;
  cv::Size size_;
};

}  // namespace headforge
