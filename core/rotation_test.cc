#include "core/rotation.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

namespace headforge {
namespace {

Eigen::Matrix3d RandomRotation(std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Quaterniond(n(*rng), n(*rng), n(*rng), n(*rng)).normalized().toRotationMatrix();
}

TEST(NearestRotation, KeepsRotationsAndAveragesNearbyOnes) {
  std::mt19937 rng(7);
  for (int i = 0; i < 20; ++i) {
    const Eigen::Matrix3d r = RandomRotation(&rng);
    EXPECT_LT((NearestRotation(r) - r).norm(), 1e-12);
    EXPECT_LT((NearestRotation(3.5 * r) - r).norm(), 1e-12);  // a positive scale does not matter
  }
  // Two rotations 10 deg either side of a third about one axis: their sum's
  // nearest rotation is the middle one.
  const Eigen::Matrix3d middle = RandomRotation(&rng);
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 3).normalized();
  const double a = 10.0 * M_PI / 180.0;
  const Eigen::Matrix3d sum = middle * Eigen::AngleAxisd(a, axis).toRotationMatrix() +
                              middle * Eigen::AngleAxisd(-a, axis).toRotationMatrix();
  EXPECT_LT((NearestRotation(sum) - middle).norm(), 1e-12);
}

TEST(NearestRotation, ReflectionsComeBackAsTheNearestProperRotation) {
  std::mt19937 rng(11);
  for (int i = 0; i < 20; ++i) {
    const Eigen::Matrix3d r = RandomRotation(&rng);
    // A reflection through the plane normal to r's third column, with the
    // third singular value the smallest: flipping that axis back is nearest.
    const Eigen::Matrix3d m = r * Eigen::Vector3d(2.0, 1.5, -0.5).asDiagonal();
    const Eigen::Matrix3d q = NearestRotation(m);
    EXPECT_NEAR(q.determinant(), 1.0, 1e-12);
    EXPECT_LT((q.transpose() * q - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_LT((q - r).norm(), 1e-12);
    // No proper rotation is nearer: compare with random ones close to it.
    for (int k = 0; k < 50; ++k) {
      const Eigen::Matrix3d other = q * Eigen::AngleAxisd(0.05, RandomRotation(&rng).col(0)).toRotationMatrix();
      EXPECT_LE((m - q).norm(), (m - other).norm() + 1e-12);
    }
  }
}

}  // namespace
}  // namespace headforge
