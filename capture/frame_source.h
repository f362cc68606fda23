// Frames of one camera, from a video file (decoded by OpenCV's ffmpeg backend)
// or a folder of images (sorted by name), read in order.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class FrameSource {
 public:
  virtual ~FrameSource() = default;

  // Opens `path` and decodes its first frame to prove it is usable. A missing
  // or unreadable path, a file that is not a video, a video with no decodable
  // frame or a folder without images each give a Status naming the path.
  // `folder_fps` is the frame rate assumed for image folders.
  static Status Open(const fs::path& path, double folder_fps, std::unique_ptr<FrameSource>* source);

  // Reads the next frame (BGR, 8-bit). `*end` becomes true past the last frame.
  virtual Status Read(cv::Mat* bgr, bool* end) = 0;
  // Skips the next frame without converting it; false past the last frame.
  virtual bool Skip() = 0;

  const std::string& path() const { return path_; }
  double fps() const { return fps_; }
  cv::Size size() const { return size_; }
  bool is_folder() const { return is_folder_; }
  // Number of frames as the container states it (exact for folders; for videos
  // an estimate, 0 when unknown). Used for progress only.
  int64_t frame_count_hint() const { return frame_count_hint_; }
  // Source file of frame `index` for image folders ("" for videos).
  virtual std::string FrameName(int64_t index) const { return ""; }

  // Presentation time of frame `index` in seconds from the first frame: for
  // a variable frame rate the container's timestamps, else index / fps().
  double TimeOf(int64_t index) const;
  // True when the container's frame intervals vary (a phone's variable frame
  // rate): frames are then sampled by their timestamps, at mean_fps() or less.
  bool variable_rate() const { return variable_rate_; }
  // The timestamps TimeOf reads (sorted; empty when unknown).
  const std::vector<double>& timestamps() const { return timestamps_; }
  // Frames per second over the whole stream (timestamps), else fps().
  double mean_fps() const { return mean_fps_ > 0.0 ? mean_fps_ : fps_; }
  // The timestamps' shortest and longest frame interval (5th and 95th
  // percentiles), in seconds; 0 without timestamps.
  double short_interval() const { return short_interval_; }
  double long_interval() const { return long_interval_; }

 protected:
  std::string path_;
  double fps_ = 0.0;
  cv::Size size_;
  bool is_folder_ = false;
  int64_t frame_count_hint_ = 0;
  std::vector<double> timestamps_;  // seconds from the first frame, sorted; empty when unknown
  bool variable_rate_ = false;
  double mean_fps_ = 0.0, short_interval_ = 0.0, long_interval_ = 0.0;

  // Sets the timestamps and what follows from them.
  void SetTimestamps(std::vector<double> times);
};

// What ffmpeg's decoder says of a video file's first video stream, decoded
// whole: its errors (damaged or truncated data) and the first of them.
// OpenCV's decoding, which ingest uses, drops damaged frames without a word.
struct StreamCheck {
  bool checked = false;     // false: the ffmpeg program could not be run
  int errors = 0;           // error lines ffmpeg printed (or 1 when it failed without one)
  std::string first_error;  // without ffmpeg's "[decoder @ address]" prefix
};
Status CheckVideoStream(const fs::path& video, StreamCheck* check);

// Image extensions an image folder may hold.
const std::vector<std::string>& ImageExtensions();

}  // namespace headforge
