#include "capture/face_mask.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace headforge {

cv::Mat HeadMaskSeeds(cv::Size size, const Landmarks68& lm) {
  cv::Mat seeds(size, CV_8U, cv::Scalar(cv::GC_BGD));
  const cv::Rect2f face = LandmarkBounds(lm);
  const float w = face.width, h = face.height;
  const cv::Point2f centre(face.x + 0.5f * w, face.y + 0.5f * h);
  // Head region: wider than the jaw (ears, hair), up to the top of the skull,
  // down past the chin for the neck.
  const cv::Point head_centre(cvRound(centre.x), cvRound(centre.y - 0.15f * h));
  cv::ellipse(seeds, head_centre, cv::Size(cvRound(1.1f * w), cvRound(1.3f * h)), 0, 0, 360,
              cv::Scalar(cv::GC_PR_BGD), cv::FILLED);
  // A band along the frame's top and sides is background wherever the head's
  // own ellipse does not reach it: in a crop round the head, GrabCut otherwise
  // has little sure background to learn its colours from, and a textured
  // backdrop can be taken for the head.
  const int band = std::max(2, cvRound(0.06f * std::max(size.width, size.height)));
  cv::Mat head_region(size, CV_8U, cv::Scalar(0));
  cv::ellipse(head_region, head_centre, cv::Size(cvRound(0.85f * w), cvRound(1.05f * h)), 0, 0, 360, cv::Scalar(255),
              cv::FILLED);
  cv::Mat border(size, CV_8U, cv::Scalar(0));
  border.rowRange(0, std::min(band, size.height)).setTo(255);
  border.colRange(0, std::min(band, size.width)).setTo(255);
  border.colRange(std::max(0, size.width - band), size.width).setTo(255);
  seeds.setTo(cv::GC_BGD, border & ~head_region);
  cv::ellipse(seeds, head_centre, cv::Size(cvRound(0.75f * w), cvRound(0.95f * h)), 0, 0, 360,
              cv::Scalar(cv::GC_PR_FGD), cv::FILLED);
  cv::rectangle(seeds, cv::Point(cvRound(centre.x - 0.3f * w), cvRound(face.y + 0.8f * h)),
                cv::Point(cvRound(centre.x + 0.3f * w), cvRound(face.y + 1.35f * h)),
                cv::Scalar(cv::GC_PR_FGD), cv::FILLED);
  // Sure foreground: the landmark hull, grown a little so that points on its
  // edge stay inside after the mask is resampled.
  std::vector<cv::Point> hull_points;
  for (const auto& p : lm) hull_points.emplace_back(cvRound(centre.x + 1.04f * (p.x - centre.x)),
                                                     cvRound(centre.y + 1.04f * (p.y - centre.y)));
  std::vector<cv::Point> hull;
  cv::convexHull(hull_points, hull);
  cv::fillConvexPoly(seeds, hull, cv::Scalar(cv::GC_FGD));
  return seeds;
}

cv::Mat HeadMask(const cv::Mat& bgr, const Landmarks68& landmarks, const HeadMaskOptions& options,
                 uint64_t seed) {
  const double scale =
      std::min(1.0, static_cast<double>(options.work_size) / std::max(bgr.cols, bgr.rows));
  cv::Mat small;
  cv::resize(bgr, small, cv::Size(), scale, scale, cv::INTER_AREA);
  Landmarks68 scaled = landmarks;
  for (auto& p : scaled) p *= static_cast<float>(scale);
  cv::Mat labels = HeadMaskSeeds(small.size(), scaled);

  const bool has_background = cv::countNonZero(labels == cv::GC_BGD) > 0 ||
                              cv::countNonZero(labels == cv::GC_PR_BGD) > 0;
  const bool has_foreground = cv::countNonZero(labels == cv::GC_FGD) > 0;
  cv::Mat foreground = (labels == cv::GC_FGD) | (labels == cv::GC_PR_FGD);
  if (has_background && has_foreground) {
    // Pixels of the frame's top, left and right edges a mask covers, then its
    // area: the smaller the better.
    auto reach = [](const cv::Mat& m) {
      const int edges = cv::countNonZero(m.row(0)) + cv::countNonZero(m.col(0)) + cv::countNonZero(m.col(m.cols - 1));
      return std::make_pair(edges, cv::countNonZero(m));
    };
    std::pair<int, int> best_reach;
    for (int attempt = 0; attempt < std::max(1, options.attempts); ++attempt) {
      cv::Mat attempt_labels = labels.clone();
      const uint64_t draw = (seed ? seed : 0x5eedULL) + 0x9e3779b97f4a7c15ULL * uint64_t(attempt);
      cv::theRNG().state = draw ? draw : 1;  // GrabCut's k-means draws from it
      cv::Mat bgd_model, fgd_model;
      cv::grabCut(small, attempt_labels, cv::Rect(), bgd_model, fgd_model, options.iterations,
                  cv::GC_INIT_WITH_MASK);
      const cv::Mat candidate = (attempt_labels == cv::GC_FGD) | (attempt_labels == cv::GC_PR_FGD);
      const std::pair<int, int> r = reach(candidate);
      if (attempt == 0 || r < best_reach) {
        best_reach = r;
        foreground = candidate;
      }
    }
  }

  // Keep the component that holds the face, then fill its holes (eyes, mouth).
  cv::Mat components;
  const int count = cv::connectedComponents(foreground, components, 8, CV_32S);
  if (count > 2) {
    const cv::Rect2f face = LandmarkBounds(scaled);
    const cv::Point centre(std::clamp(cvRound(face.x + 0.5f * face.width), 0, small.cols - 1),
                           std::clamp(cvRound(face.y + 0.5f * face.height), 0, small.rows - 1));
    const int keep = components.at<int>(centre);
    if (keep > 0) foreground = components == keep;
  }
  // Background pixels reachable from the border are true background; the rest
  // of the background (holes inside the head) becomes foreground.
  const cv::Mat inverted = ~foreground;
  cv::Mat reach(foreground.rows + 2, foreground.cols + 2, CV_8U, cv::Scalar(0));
  inverted.copyTo(reach(cv::Rect(1, 1, foreground.cols, foreground.rows)));
  reach.row(0).setTo(255);
  reach.row(reach.rows - 1).setTo(255);
  reach.col(0).setTo(255);
  reach.col(reach.cols - 1).setTo(255);
  cv::floodFill(reach, cv::Point(0, 0), cv::Scalar(128));
  const cv::Mat outside = reach(cv::Rect(1, 1, foreground.cols, foreground.rows)) == 128;
  const cv::Mat filled = ~outside;

  cv::Mat mask;
  cv::resize(filled, mask, bgr.size(), 0, 0, cv::INTER_LINEAR);
  cv::threshold(mask, mask, 127, 255, cv::THRESH_BINARY);
  return mask;
}

}  // namespace headforge
