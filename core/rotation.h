// Rotations shared by the solvers and the tests.
#pragma once

#include <Eigen/Core>
#include <Eigen/SVD>

namespace headforge {

// The rotation nearest to `m` in the Frobenius norm (its polar factor, with
// the determinant forced to +1). For a weighted sum of rotations this is
// their chordal mean.
inline Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  if ((u * svd.matrixV().transpose()).determinant() < 0) u.col(2) *= -1;  // the smallest singular value's axis
  return u * svd.matrixV().transpose();
}

}  // namespace headforge
