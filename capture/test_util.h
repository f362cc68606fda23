// Helpers shared by the capture tests: GRID clips from the shared data folder
// and scratch folders.
#pragma once

#include <gtest/gtest.h>

#include <opencv2/videoio.hpp>
#include <string>
#include <vector>

#include "core/fs.h"

namespace headforge::testing {

inline fs::path SharedData() { return HEADFORGE_TEST_SHARED_DATA; }
inline fs::path GridClip(const std::string& name) {
  return SharedData() / "video" / "grid" / (name + ".mpg");
}

// A fresh folder named after the running test.
inline fs::path ScratchDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir = fs::temp_directory_path() /
                       ("hf_" + std::string(info->test_suite_name()) + "_" + info->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// The first `count` frames of a GRID clip (BGR).
inline std::vector<cv::Mat> GridFrames(const std::string& name, int count) {
  cv::VideoCapture capture(GridClip(name).string(), cv::CAP_FFMPEG);
  std::vector<cv::Mat> frames;
  cv::Mat frame;
  while (static_cast<int>(frames.size()) < count && capture.read(frame)) frames.push_back(frame.clone());
  return frames;
}

}  // namespace headforge::testing
