// Crops of source frames into output frames, and the pixel mapping between them.
//
// Pixel coordinates follow OpenCV: the centre of pixel (i, j) is at (i, j). A
// crop with top-left corner (x0, y0) (pixel edges) and scale s maps
//   u_out = (u_src + 0.5 - x0) * s - 0.5
// so intrinsics map as f_out = s f_src, c_out = (c_src + 0.5 - x0) s - 0.5.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "capture/landmarks.h"

namespace headforge {

struct CropWindow {
  double x0 = 0.0, y0 = 0.0;  // top-left corner in source pixels (pixel edges)
  double width = 0.0, height = 0.0;  // extent in source pixels
  double scale = 1.0;                // output pixels per source pixel
  cv::Size output;                   // output image size

  cv::Point2f Map(const cv::Point2f& source) const;
  // Crops and resizes; regions outside the source are black (or, with
  // cv::BORDER_REPLICATE, its edge pixels repeated).
  cv::Mat Apply(const cv::Mat& source, int interpolation, int border = cv::BORDER_CONSTANT) const;
  // Whether the window reaches outside a source of `size`.
  bool Exceeds(cv::Size size) const;
};

// A square crop of side `side` centred at `centre`, scaled to `resolution`.
CropWindow SquareCrop(const cv::Point2d& centre, double side, int resolution);
// The whole frame with its longer side scaled to `resolution`.
CropWindow FullFrameCrop(cv::Size source, int resolution);

// The face centre and size (landmark extent) that crops are built from.
struct FaceFrame {
  cv::Point2d centre;
  double size = 0.0;
};
FaceFrame FaceFrameOf(const Landmarks68& landmarks);

// One square holding, for every frame, the square of side `crop_scale` x the
// median face size around that frame's face centre.
CropWindow SequenceCrop(const std::vector<FaceFrame>& faces, double crop_scale, int resolution);
// A square per frame, of fixed side (median face size x `crop_scale`), centred
// on the face centre smoothed over +-`radius` frames.
std::vector<CropWindow> FollowingCrops(const std::vector<FaceFrame>& faces, double crop_scale,
                                       int resolution, int radius = 3);

}  // namespace headforge
