#include "capture/crop.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

namespace headforge {
namespace {

// The brightest pixel of a crop must sit where Map() sends the source dot.
void ExpectDotMapped(const CropWindow& crop, cv::Size source_size, cv::Point dot) {
  cv::Mat source(source_size, CV_8UC1, cv::Scalar(0));
  cv::circle(source, dot, 3, cv::Scalar(255), cv::FILLED);
  const cv::Mat out = crop.Apply(source, cv::INTER_LINEAR);
  ASSERT_EQ(out.size(), crop.output);
  cv::Moments m = cv::moments(out, false);
  ASSERT_GT(m.m00, 0.0);
  const cv::Point2f centroid(m.m10 / m.m00, m.m01 / m.m00);
  const cv::Point2f expected = crop.Map(cv::Point2f(dot));
  EXPECT_NEAR(centroid.x, expected.x, 0.5) << "scale " << crop.scale;
  EXPECT_NEAR(centroid.y, expected.y, 0.5) << "scale " << crop.scale;
}

TEST(Crop, MapAgreesWithImageWhenEnlarging) {
  ExpectDotMapped(SquareCrop({150.0, 120.0}, 100.0, 256), {360, 288}, {170, 100});
}

TEST(Crop, MapAgreesWithImageWhenShrinking) {
  ExpectDotMapped(SquareCrop({500.0, 400.0}, 800.0, 256), {1000, 800}, {620, 310});
}

TEST(Crop, FullFrameKeepsAspectAndCorners) {
  const CropWindow crop = FullFrameCrop({360, 288}, 512);
  EXPECT_EQ(crop.output, cv::Size(512, 410));
  // Pixel edges map to pixel edges.
  EXPECT_NEAR(crop.Map({-0.5f, -0.5f}).x, -0.5, 1e-5);
  EXPECT_NEAR(crop.Map({359.5f, 0.0f}).x, 511.5, 1e-3);
  ExpectDotMapped(crop, {360, 288}, {40, 250});
}

TEST(Crop, OutsideTheSourceIsBlack) {
  cv::Mat source(100, 100, CV_8UC3, cv::Scalar(200, 200, 200));
  const CropWindow crop = SquareCrop({10.0, 10.0}, 60.0, 60);
  const cv::Mat out = crop.Apply(source, cv::INTER_LINEAR);
  EXPECT_EQ(out.at<cv::Vec3b>(2, 2), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(out.at<cv::Vec3b>(50, 50), cv::Vec3b(200, 200, 200));
}

TEST(Crop, SequenceCropHoldsEveryFace) {
  std::vector<FaceFrame> faces = {{{100, 100}, 50}, {{160, 110}, 52}, {{130, 90}, 48}};
  const CropWindow crop = SequenceCrop(faces, 2.0, 256);
  // Every face's square (2 x the median size 50, centred on the face) is inside;
  // crop edges are pixel edges, face centres pixel centres (+0.5 between them).
  for (const auto& f : faces) {
    EXPECT_LE(crop.x0, f.centre.x + 0.5 - 50.0);
    EXPECT_GE(crop.x0 + crop.width, f.centre.x + 0.5 + 50.0);
    EXPECT_LE(crop.y0, f.centre.y + 0.5 - 50.0);
    EXPECT_GE(crop.y0 + crop.height, f.centre.y + 0.5 + 50.0);
  }
  EXPECT_DOUBLE_EQ(crop.width, crop.height);
}

}  // namespace
}  // namespace headforge
