#include "capture/frame_source.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "core/image_io.h"
#include "core/process.h"

namespace headforge {

const std::vector<std::string>& ImageExtensions() {
  static const std::vector<std::string> extensions = {".png", ".jpg", ".jpeg", ".bmp", ".tif",
                                                      ".tiff", ".webp"};
  return extensions;
}

namespace {

cv::Mat ToBgr8(const cv::Mat& image) {
  cv::Mat out = image;
  if (out.depth() != CV_8U) out.convertTo(out, CV_8U, out.depth() == CV_16U ? 1.0 / 257.0 : 1.0);
  if (out.channels() == 1) cv::cvtColor(out, out, cv::COLOR_GRAY2BGR);
  if (out.channels() == 4) cv::cvtColor(out, out, cv::COLOR_BGRA2BGR);
  return out;
}

// The lines ffprobe prints for `args` (after the program's name and before
// the path); none when it fails or cannot be run.
std::vector<std::string> ProbeLines(const std::vector<std::string>& args, const fs::path& path) {
  static std::atomic<int> counter{0};
  const fs::path log = fs::temp_directory_path() / ("hf_probe_" + std::to_string(::getpid()) + "_" +
                                                    std::to_string(counter++) + ".txt");
  std::error_code ec;
  fs::remove(log, ec);
  std::vector<std::string> command = {"ffprobe", "-v", "quiet"};
  command.insert(command.end(), args.begin(), args.end());
  command.push_back(path.string());
  int exit_code = 0;
  std::vector<std::string> lines;
  if (RunProgram(command, log, &exit_code).ok() && exit_code == 0) {
    std::ifstream in(log);
    for (std::string line; std::getline(in, line);)
      if (!line.empty()) lines.push_back(line);
  }
  fs::remove(log, ec);
  return lines;
}

// The kinds of the streams ffprobe finds in `path` ("video", "audio", ...).
std::vector<std::string> StreamKinds(const fs::path& path) {
  return ProbeLines({"-show_entries", "stream=codec_type", "-of", "csv=p=0"}, path);
}

// The presentation times of the first video stream's packets, sorted, in
// seconds (read from the container, nothing decoded); empty when a packet has
// none or ffprobe cannot be run.
std::vector<double> PacketTimes(const fs::path& path) {
  std::vector<double> times;
  for (const std::string& line :
       ProbeLines({"-select_streams", "v:0", "-show_entries", "packet=pts_time,flags", "-of", "csv=p=0"}, path)) {
    // "0.040000,K__": packets flagged D (discarded: an edit list cut them)
    // never become frames.
    const size_t comma = line.find(',');
    if (comma != std::string::npos && line.find('D', comma) != std::string::npos) continue;
    char* end = nullptr;
    const double t = std::strtod(line.c_str(), &end);
    if (end == line.c_str() || !std::isfinite(t)) return {};  // "N/A"
    times.push_back(t);
  }
  std::sort(times.begin(), times.end());
  return times;
}

// Why `path` gives no frame: no video stream at all, or a stream ffmpeg cannot decode.
Status NoFrames(const std::string& path, const std::string& otherwise) {
  const std::vector<std::string> kinds = StreamKinds(path);
  if (!kinds.empty() && std::find(kinds.begin(), kinds.end(), "video") == kinds.end()) {
    std::string list;
    for (const std::string& k : kinds) list += (list.empty() ? "" : ", ") + k;
    return Status::DataError(path + " holds no video stream (only " + list + "); give a video file or a folder of "
                             "images");
  }
  return Status::DataError(otherwise);
}

// ffmpeg's own lines ("moov atom not found", "error while decoding MB")
// would reach stderr beside the one-line reason ingest gives; they are
// silenced unless the user asks for them (OPENCV_FFMPEG_LOGLEVEL or
// OPENCV_FFMPEG_DEBUG set). OpenCV reads these when it opens its first video.
void QuietFfmpegUnlessAsked() {
  static const bool quiet = [] {
    if (std::getenv("OPENCV_FFMPEG_LOGLEVEL") || std::getenv("OPENCV_FFMPEG_DEBUG")) return false;
    return ::setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", 0) == 0;  // AV_LOG_QUIET
  }();
  (void)quiet;
}

class VideoFrameSource : public FrameSource {
 public:
  Status OpenVideo(const fs::path& path) {
    QuietFfmpegUnlessAsked();
    path_ = path.string();
    if (!capture_.open(path_, cv::CAP_FFMPEG))
      return NoFrames(path_, "cannot decode " + path_ +
                                 ": ffmpeg does not recognise it as a video (corrupt, truncated or an "
                                 "unsupported format? try re-encoding it with ffmpeg)");
    fps_ = capture_.get(cv::CAP_PROP_FPS);
    if (!(fps_ > 0.0 && fps_ < 1000.0)) fps_ = 25.0;
    frame_count_hint_ = std::max<int64_t>(0, static_cast<int64_t>(capture_.get(cv::CAP_PROP_FRAME_COUNT)));
    // Decode the first frame now so a file without decodable frames fails early.
    if (!capture_.read(first_) || first_.empty())
      return NoFrames(path_, path_ + " holds no decodable video frame (corrupt, truncated or empty file?)");
    first_ = ToBgr8(first_);
    size_ = first_.size();
    SetTimestamps(PacketTimes(path));
    return Status::Ok();
  }

  Status Read(cv::Mat* bgr, bool* end) override {
    *end = false;
    if (!first_.empty()) {
      *bgr = first_;
      first_.release();
      return Status::Ok();
    }
    cv::Mat frame;
    if (!capture_.read(frame) || frame.empty()) {
      *end = true;
      return Status::Ok();
    }
    *bgr = ToBgr8(frame);
    if (bgr->size() != size_)
      return Status::DataError(path_ + ": frame size changed mid-stream");
    return Status::Ok();
  }

  bool Skip() override {
    if (!first_.empty()) {
      first_.release();
      return true;
    }
    return capture_.grab();
  }

 private:
  cv::VideoCapture capture_;
  cv::Mat first_;  // decoded by OpenVideo, handed out by the first Read
};

class FolderFrameSource : public FrameSource {
 public:
  Status OpenFolder(const fs::path& path, double fps) {
    path_ = path.string();
    is_folder_ = true;
    fps_ = fps;
    files_ = ListFiles(path, ImageExtensions());
    if (files_.empty()) {
      // A capture of several cameras (the simulator's, a studio's export):
      // one folder of images per camera.
      std::vector<std::string> cameras;
      std::error_code ec;
      for (const auto& entry : fs::directory_iterator(path, ec))
        if (entry.is_directory(ec) && !ListFiles(entry.path(), ImageExtensions()).empty())
          cameras.push_back(entry.path().string());
      std::sort(cameras.begin(), cameras.end());
      std::string hint;
      for (const std::string& c : cameras) hint += " " + c;
      if (!cameras.empty())
        return Status::DataError("folder " + path_ + " holds no images, but " + std::to_string(cameras.size()) +
                                 " of its folders do: give one folder per camera, --video" + hint);
      return Status::DataError("folder " + path_ + " holds no images (.png, .jpg, ...)");
    }
    cv::Mat first;
    HF_RETURN_IF_ERROR(ReadImage(files_[0], &first, cv::IMREAD_UNCHANGED));
    size_ = first.size();
    frame_count_hint_ = static_cast<int64_t>(files_.size());
    return Status::Ok();
  }

  Status Read(cv::Mat* bgr, bool* end) override {
    *end = next_ >= files_.size();
    if (*end) return Status::Ok();
    cv::Mat image;
    HF_RETURN_IF_ERROR(ReadImage(files_[next_++], &image, cv::IMREAD_UNCHANGED));
    *bgr = ToBgr8(image);
    if (bgr->size() != size_)
      return Status::DataError(files_[next_ - 1].string() + " differs in size from the folder's first image");
    return Status::Ok();
  }

  bool Skip() override {
    if (next_ >= files_.size()) return false;
    ++next_;
    return true;
  }

  std::string FrameName(int64_t index) const override {
    return index >= 0 && static_cast<size_t>(index) < files_.size() ? files_[index].filename().string()
                                                                     : "";
  }

 private:
  std::vector<fs::path> files_;
  size_t next_ = 0;
};

}  // namespace

void FrameSource::SetTimestamps(std::vector<double> times) {
  timestamps_.clear();
  variable_rate_ = false;
  mean_fps_ = short_interval_ = long_interval_ = 0.0;
  if (times.size() < 3) return;
  for (double& t : times) t -= times.front();
  std::vector<double> intervals;
  for (size_t i = 1; i < times.size(); ++i) intervals.push_back(times[i] - times[i - 1]);
  std::sort(intervals.begin(), intervals.end());
  short_interval_ = intervals[intervals.size() / 20];
  long_interval_ = intervals[intervals.size() - 1 - intervals.size() / 20];
  if (!(short_interval_ > 0.0) || !(times.back() > 0.0)) return;  // repeated timestamps: not to be trusted
  timestamps_ = std::move(times);
  mean_fps_ = (timestamps_.size() - 1) / timestamps_.back();
  // A phone's jitter round a constant rate (33 +- 5 ms) stays below this.
  variable_rate_ = long_interval_ > 1.5 * short_interval_;
}

double FrameSource::TimeOf(int64_t index) const {
  // A constant rate is timed by index: the packets need not map one to one
  // onto the frames OpenCV decodes, and only a variable rate needs them.
  if (variable_rate_ && index >= 0 && static_cast<size_t>(index) < timestamps_.size()) return timestamps_[index];
  return fps_ > 0.0 ? index / fps_ : 0.0;
}

Status FrameSource::Open(const fs::path& path, double folder_fps,
                         std::unique_ptr<FrameSource>* source) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Status::NotFound("input not found: " + path.string());
  if (fs::is_directory(path, ec)) {
    auto folder = std::make_unique<FolderFrameSource>();
    HF_RETURN_IF_ERROR(folder->OpenFolder(path, folder_fps));
    *source = std::move(folder);
    return Status::Ok();
  }
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "video"));
  if (fs::file_size(path, ec) == 0) return Status::DataError("video file " + path.string() + " is empty");
  auto video = std::make_unique<VideoFrameSource>();
  HF_RETURN_IF_ERROR(video->OpenVideo(path));
  *source = std::move(video);
  return Status::Ok();
}

Status CheckVideoStream(const fs::path& video, StreamCheck* check) {
  *check = StreamCheck();
  static std::atomic<int> counter{0};
  const fs::path log = fs::temp_directory_path() / ("hf_stream_check_" + std::to_string(::getpid()) + "_" +
                                                    std::to_string(counter++) + ".log");
  std::error_code ec;
  fs::remove(log, ec);
  int exit_code = 0;
  const Status run = RunProgram({"ffmpeg", "-nostdin", "-hide_banner", "-v", "error", "-i", video.string(), "-map",
                                 "0:v:0", "-f", "null", "-"},
                                log, &exit_code);
  if (run.code() == Status::Code::kNotFound) return Status::Ok();  // no ffmpeg: unchecked
  HF_RETURN_IF_ERROR(run);
  check->checked = true;
  std::ifstream in(log);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    if (check->errors++ == 0) {
      // "[mpeg1video @ 0x55d0c0a5c400] ac-tex damaged at 6 15" -> "ac-tex damaged at 6 15"
      const size_t close = line.find("] ");
      check->first_error = line[0] == '[' && close != std::string::npos ? line.substr(close + 2) : line;
    }
  }
  fs::remove(log, ec);
  if (exit_code != 0 && check->errors == 0) {
    check->errors = 1;
    check->first_error = "ffmpeg stopped with exit code " + std::to_string(exit_code);
  }
  return Status::Ok();
}

}  // namespace headforge
