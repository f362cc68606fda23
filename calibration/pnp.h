// The pose of a known 3D point set from its image (perspective-n-point), with
// a check of the configuration before trusting the answer.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace headforge {

enum class PnpQuality {
  kGood,
  kNearlyDegenerate,  // points close to a line: the rotation about it is poorly determined
  kFailed,
};
const char* PnpQualityName(PnpQuality quality);

struct PnpResult {
  bool ok = false;
  PnpQuality quality = PnpQuality::kFailed;
  Eigen::Isometry3d cam_from_object = Eigen::Isometry3d::Identity();
  double rms_px = 0.0;
  std::string message;
};

// `object` in the object frame, `pixels` in the image of a pinhole camera `k`
// (no distortion). At least 4 points.
PnpResult SolvePnp(const std::vector<Eigen::Vector3d>& object, const std::vector<Eigen::Vector2d>& pixels,
                   const Eigen::Matrix3d& k);

}  // namespace headforge
