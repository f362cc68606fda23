// Similarity transforms between point sets: the closed-form least-squares
// solution of Umeyama ("Least-squares estimation of transformation parameters
// between two point patterns", IEEE PAMI 13(4), 1991), and a RANSAC wrapper for
// sets with outliers. Used to align a reconstruction to the face model.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

namespace headforge {

// x_tgt = scale * rotation * x_src + translation.
struct Sim3 {
  double scale = 1.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return scale * (rotation * x) + translation; }
  Sim3 Inverse() const;
  Eigen::Matrix4d Matrix() const;
};

// How far a solution can be trusted.
enum class SimilarityQuality {
  kGood,        // well-conditioned
  kPlanar,      // source points (nearly) coplanar: unique, but sensitive to noise off the plane
  kReflection,  // the best fit would be a reflection; the rotation returned is the best proper one
  kDegenerate,  // fewer than 3 distinct, non-collinear points: no unique solution, nothing returned
};
const char* SimilarityQualityName(SimilarityQuality quality);

struct SimilarityResult {
  bool ok = false;  // false only when degenerate (or no RANSAC consensus)
  SimilarityQuality quality = SimilarityQuality::kDegenerate;
  Sim3 tgt_from_src;
  double rms = 0.0;          // residual over the inliers, target units
  std::vector<int> inliers;  // indices used in the final fit
  std::string message;       // why a result is degenerate or flagged
};

// Least squares over all pairs; src and tgt are [3, N]. Coordinates are
// normalised internally, so scales from 1e-6 to 1e6 are handled alike.
SimilarityResult EstimateSimilarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& tgt);

struct RansacOptions {
  double inlier_threshold = 0.005;  // target units (metres for the head frame)
  int max_iterations = 2000;
  double confidence = 0.999;
  int min_inliers = 3;
  uint64_t seed = 0;
};

// RANSAC over minimal samples of 3, then a least-squares refit on the inliers.
SimilarityResult EstimateSimilarityRansac(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& tgt,
                                          const RansacOptions& options);

}  // namespace headforge
