#include "capture/background_motion.h"

#include <algorithm>
#include <cstdio>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/statistics.h"

namespace headforge {

namespace {
constexpr int kMinFollowed = 20;        // features needed to trust their median motion
constexpr double kMinChangeGrey = 5.0;  // background change (grey levels) of a camera that moved
}  // namespace

bool BackgroundMotion::Moving(double threshold_px) const {
  if (followed >= kMinFollowed) return median_px > threshold_px;
  if (change >= kMinChangeGrey) return true;  // features lost rather than followed
  return 0.0 > threshold_px;  // nothing shows motion: none
}

std::string BackgroundMotion::Describe() const {
  char text[200];
  if (followed >= kMinFollowed)
    std::snprintf(text, sizeof(text), "the background moves %.1f px between frames", median_px);
  else if (change >= kMinChangeGrey)
    std::snprintf(text, sizeof(text),
                  "the background changes by %.0f grey levels between frames and optical flow follows %d features "
                  "of it",
                  change, followed);
  else
    std::snprintf(text, sizeof(text), "the background shows no motion (%d features followed, change %.0f grey levels)",
                  followed, change);
  return text;
}

Status MeasureBackgroundMotion(const IngestedCapture& capture, const std::string& camera, BackgroundMotion* motion) {
  *motion = BackgroundMotion();
  const IngestedCamera* cam = nullptr;
  for (const auto& c : capture.cameras)
    if (c.name == camera) cam = &c;
  if (!cam || cam->frames.size() < 2) return Status::Ok();
  // Background: off the head mask by a margin, above the mouth (shoulders and
  // body reach up to the chin and move with the head), and not the black
  // padding of a crop.
  auto background_of = [&](const cv::Mat& image, const IngestedFrame& frame) {
    cv::Mat mask = cv::imread(capture.MaskPath(camera, frame.index).string(), cv::IMREAD_GRAYSCALE);
    cv::Mat background = mask.empty() ? cv::Mat(image.size(), CV_8U, cv::Scalar(255)) : (mask == 0);
    cv::erode(background, background, cv::Mat(), cv::Point(-1, -1), std::max(5, image.cols / 30));
    if (const auto& lm = frame.landmarks) {
      const int mouth =
          std::clamp(static_cast<int>(std::min((*lm)[ibug::kMouthRight].y, (*lm)[ibug::kMouthLeft].y)), 0, image.rows);
      background.rowRange(mouth, image.rows).setTo(0);
    }
    background &= image > 2;
    return background;
  };
  // Five frames spread over the sequence, each read once; neighbours form the pairs.
  const int n = static_cast<int>(cam->frames.size());
  std::vector<int> sampled;
  for (int k = 0; k <= 4; ++k)
    if (sampled.empty() || k * (n - 1) / 4 != sampled.back()) sampled.push_back(k * (n - 1) / 4);
  std::vector<cv::Mat> images, backgrounds;
  for (int s : sampled) {
    images.push_back(cv::imread(capture.FramePath(camera, cam->frames[s].index).string(), cv::IMREAD_GRAYSCALE));
    if (images.back().empty() || images.back().size() != images.front().size())
      return Status::DataError("cannot read frames of " + camera);
    backgrounds.push_back(background_of(images.back(), cam->frames[s]));
  }
  std::vector<double> motions, changes;
  for (size_t p = 0; p + 1 < images.size(); ++p) {
    const cv::Mat &ia = images[p], &ib = images[p + 1], &background = backgrounds[p];
    // Grey-level change over the background both frames show, less the
    // median difference (a change of exposure).
    const cv::Mat both = background & backgrounds[p + 1];
    std::vector<double> differences;
    for (int y = 0; y < ia.rows; ++y)
      for (int x = 0; x < ia.cols; ++x)
        if (both.at<uint8_t>(y, x)) differences.push_back(double(ia.at<uint8_t>(y, x)) - double(ib.at<uint8_t>(y, x)));
    if (differences.size() >= 1000) {
      const double offset = Median(differences);
      for (double& d : differences) d = std::abs(d - offset);
      changes.push_back(Median(differences));
    }
    std::vector<cv::Point2f> pa, pb;
    cv::goodFeaturesToTrack(ia, pa, 300, 0.01, 5, background);
    if (pa.size() < 10) continue;
    std::vector<uchar> ok, back_ok;
    std::vector<float> err;
    std::vector<cv::Point2f> back;
    cv::calcOpticalFlowPyrLK(ia, ib, pa, pb, ok, err);
    cv::calcOpticalFlowPyrLK(ib, ia, pb, back, back_ok, err);
    // Only tracks that come back to where they started: flat or noisy regions
    // (a plain backdrop under compression) give no trustworthy motion.
    for (size_t i = 0; i < pa.size(); ++i)
      if (ok[i] && back_ok[i] && cv::norm(back[i] - pa[i]) < 0.3) motions.push_back(cv::norm(pb[i] - pa[i]));
  }
  motion->followed = static_cast<int>(motions.size());
  motion->median_px = Median(motions);
  motion->change = Median(changes);
  return Status::Ok();
}

}  // namespace headforge
