// Multi-view triangulation of one point: the linear (DLT) solution (Hartley &
// Zisserman, "Multiple View Geometry", 2nd ed., sec. 12.2), refined by
// minimising the reprojection error with a robust loss.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace headforge {

struct TriangulationView {
  Eigen::Matrix<double, 3, 4> projection;  // K [R | t], pixels
  Eigen::Vector2d pixel;
  double weight = 1.0;
};

enum class TriangulationQuality {
  kGood,
  kLowParallax,  // rays meet at a small angle: depth is poorly determined
  kFailed,       // no finite point in front of the cameras
};
const char* TriangulationQualityName(TriangulationQuality quality);

struct TriangulationOptions {
  double min_angle_deg = 2.0;     // below: kLowParallax
  double robust_scale_px = 2.0;   // Cauchy loss scale of the refinement
  bool refine = true;
};

struct TriangulationResult {
  bool ok = false;
  TriangulationQuality quality = TriangulationQuality::kFailed;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  double max_angle_deg = 0.0;  // largest angle between two rays
  double rms_px = 0.0;         // reprojection error over the views
  std::string message;
};

TriangulationResult TriangulatePoint(const std::vector<TriangulationView>& views,
                                     const TriangulationOptions& options = TriangulationOptions());

// The centre of the camera with projection matrix P.
Eigen::Vector3d ProjectionCentre(const Eigen::Matrix<double, 3, 4>& projection);

}  // namespace headforge
