#include "core/video_writer.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace headforge {
namespace {

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_video_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Frames written are read back by OpenCV: their count, size, and a square
// that moves across them where it was drawn.
TEST(VideoFileWriter, WritesAVideoThatReadsBack) {
  const fs::path path = Scratch("ok") / "clip.mp4";
  VideoFileWriter writer;
  ASSERT_TRUE(writer.Open(path, 10, cv::Size(64, 48)).ok());
  for (int i = 0; i < 12; ++i) {
    cv::Mat frame(48, 64, CV_8UC3, cv::Scalar(40, 40, 40));
    cv::rectangle(frame, cv::Rect(4 * i, 16, 12, 12), cv::Scalar(255, 255, 255), cv::FILLED);
    ASSERT_TRUE(writer.Write(frame).ok());
  }
  ASSERT_TRUE(writer.Close().ok());
  cv::VideoCapture read(path.string());
  ASSERT_TRUE(read.isOpened());
  int count = 0;
  for (cv::Mat frame; read.read(frame); ++count) {
    ASSERT_EQ(frame.size(), cv::Size(64, 48));
    cv::Mat grey;
    cv::cvtColor(frame, grey, cv::COLOR_BGR2GRAY);
    const cv::Moments m = cv::moments(grey > 128, true);
    ASSERT_GT(m.m00, 0) << count;
    EXPECT_NEAR(m.m10 / m.m00, 4 * count + 5.5, 2.0) << count;  // the square's centre
  }
  EXPECT_EQ(count, 12);
}

TEST(VideoFileWriter, BadFramesAndUnwritablePlacesAreErrors) {
  VideoFileWriter writer;
  EXPECT_FALSE(writer.Write(cv::Mat(48, 64, CV_8UC3)).ok());  // not open
  const Status missing = writer.Open(Scratch("bad") / "no" / "such" / "dir" / "clip.mp4", 10, cv::Size(64, 48));
  EXPECT_EQ(missing.code(), Status::Code::kIoError);
  const fs::path path = Scratch("size") / "clip.mp4";
  ASSERT_TRUE(writer.Open(path, 10, cv::Size(64, 48)).ok());
  EXPECT_FALSE(writer.Write(cv::Mat(32, 32, CV_8UC3)).ok());  // another size
  // The file removed under the writer: Close says the video was not written.
  ASSERT_TRUE(writer.Write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(9, 9, 9))).ok());
  fs::remove(path);
  const Status closed = writer.Close();
  EXPECT_EQ(closed.code(), Status::Code::kIoError);
  EXPECT_NE(closed.message().find("clip.mp4"), std::string::npos) << closed.message();
}

}  // namespace
}  // namespace headforge
