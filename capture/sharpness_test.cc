#include "capture/sharpness.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "capture/test_util.h"

namespace headforge {
namespace {

TEST(Sharpness, FlagsTheFrameBlurredOnPurpose) {
  auto frames = headforge::testing::GridFrames("lbbc2a", 30);
  ASSERT_EQ(frames.size(), 30u);
  cv::GaussianBlur(frames[13], frames[13], cv::Size(0, 0), 2.5);
  std::vector<double> sharpness;
  for (const auto& f : frames) sharpness.push_back(LaplacianVariance(f));
  double median = 0.0;
  const auto blurred = BlurredFrames(sharpness, 0.35, &median);
  EXPECT_GT(median, 0.0);
  for (int i = 0; i < 30; ++i) EXPECT_EQ(blurred[i], i == 13) << "frame " << i;
}

TEST(Sharpness, RatioZeroKeepsEverything) {
  double median = 0.0;
  const auto blurred = BlurredFrames({1.0, 100.0, 100.0}, 0.0, &median);
  EXPECT_EQ(median, 100.0);
  for (bool b : blurred) EXPECT_FALSE(b);
}

TEST(Sharpness, FlatImageHasZeroVariance) {
  EXPECT_DOUBLE_EQ(LaplacianVariance(cv::Mat(50, 50, CV_8UC3, cv::Scalar(90, 90, 90))), 0.0);
}

}  // namespace
}  // namespace headforge
