#include "calibration/pnp.h"

#include <Eigen/SVD>
#include <cmath>
#include <opencv2/calib3d.hpp>

namespace headforge {

const char* PnpQualityName(PnpQuality q) {
  switch (q) {
    case PnpQuality::kGood: return "good";
    case PnpQuality::kNearlyDegenerate: return "nearly-degenerate";
    case PnpQuality::kFailed: return "failed";
  }
  return "failed";
}

PnpResult SolvePnp(const std::vector<Eigen::Vector3d>& object, const std::vector<Eigen::Vector2d>& pixels,
                   const Eigen::Matrix3d& k) {
  PnpResult r;
  if (object.size() != pixels.size() || object.size() < 4) {
    r.message = "need at least 4 point pairs, got " + std::to_string(std::min(object.size(), pixels.size()));
    return r;
  }
  Eigen::Matrix3Xd points(3, object.size());
  for (size_t i = 0; i < object.size(); ++i) {
    if (!object[i].allFinite() || !pixels[i].allFinite()) {
      r.message = "non-finite input";
      return r;
    }
    points.col(i) = object[i];
  }
  const Eigen::Matrix3Xd centred = points.colwise() - points.rowwise().mean();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3Xd>(centred).singularValues();
  if (!(sv[0] > 0) || sv[1] / sv[0] < 1e-6) {
    r.message = "the 3D points are collinear: the pose is not determined";
    return r;
  }
  std::vector<cv::Point3d> cv_object;
  std::vector<cv::Point2d> cv_pixels;
  for (size_t i = 0; i < object.size(); ++i) {
    cv_object.emplace_back(object[i].x(), object[i].y(), object[i].z());
    cv_pixels.emplace_back(pixels[i].x(), pixels[i].y());
  }
  const cv::Matx33d camera(k(0, 0), k(0, 1), k(0, 2), k(1, 0), k(1, 1), k(1, 2), k(2, 0), k(2, 1), k(2, 2));
  cv::Mat rvec, tvec;
  bool solved = false;
  try {
    solved = cv::solvePnP(cv_object, cv_pixels, camera, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_SQPNP);
    if (solved) solved = cv::solvePnP(cv_object, cv_pixels, camera, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
  } catch (const cv::Exception& e) {
    r.message = std::string("PnP failed: ") + e.what();
    return r;
  }
  if (!solved || !cv::checkRange(rvec) || !cv::checkRange(tvec)) {
    r.message = "PnP found no pose";
    return r;
  }
  cv::Mat rot;
  cv::Rodrigues(rvec, rot);
  Eigen::Matrix3d rotation;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rotation(i, j) = rot.at<double>(i, j);
  r.cam_from_object.linear() = rotation;
  r.cam_from_object.translation() = Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  double sum = 0;
  int behind = 0;
  for (size_t i = 0; i < object.size(); ++i) {
    const Eigen::Vector3d p = r.cam_from_object * object[i];
    behind += p.z() <= 0;
    const Eigen::Vector3d h = k * p;
    sum += (h.head<2>() / h.z() - pixels[i]).squaredNorm();
  }
  r.rms_px = std::sqrt(sum / static_cast<double>(object.size()));
  if (behind > 0 || !std::isfinite(r.rms_px)) {
    r.message = "the pose puts points behind the camera";
    return r;
  }
  r.ok = true;
  r.quality = sv[1] / sv[0] < 0.05 ? PnpQuality::kNearlyDegenerate : PnpQuality::kGood;
  if (r.quality == PnpQuality::kNearlyDegenerate) r.message = "points lie close to a line";
  return r;
}

}  // namespace headforge
