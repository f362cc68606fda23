// Each tracking cost's derivatives against numeric differentiation
// (ceres::GradientChecker).
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <random>

#include "calibration/reprojection_cost.h"
#include "reconstruction/tracking_costs.h"

namespace headforge {
namespace {

// A small random basis: 68 landmarks near a face-sized blob, 4 identity and 5
// expression modes of millimetre scale.
LandmarkBasis RandomBasis(int k, int e, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  LandmarkBasis b;
  b.num_identity = k;
  b.num_expressions = e;
  b.base.resize(3, 68);
  for (int i = 0; i < 68; ++i) {
    b.base.col(i) = Eigen::Vector3d(0.05 * n(rng), 0.05 * n(rng), 0.1 + 0.02 * n(rng));
    Eigen::Matrix<double, 3, Eigen::Dynamic> id(3, k), ex(3, e);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < k; ++c) id(r, c) = 0.003 * n(rng);
      for (int c = 0; c < e; ++c) ex(r, c) = 0.01 * n(rng);
    }
    b.identity.push_back(id);
    b.expression.push_back(ex);
  }
  return b;
}

void ExpectGradientsMatch(const ceres::CostFunction* cost, const std::vector<const double*>& parameters) {
  ceres::NumericDiffOptions numeric;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(cost, no_manifolds, numeric);
  ceres::GradientChecker::ProbeResults results;
  EXPECT_TRUE(checker.Probe(parameters.data(), 1e-7, &results)) << results.error_log;
  EXPECT_LT(results.maximum_relative_error, 1e-7);
}

TEST(TrackingCosts, LandmarkReprojectionGradients) {
  const LandmarkBasis basis = RandomBasis(4, 5, 1);
  TrackingCamera camera;
  camera.fx = 800;
  camera.fy = 810;
  camera.cx = 250;
  camera.cy = 260;
  camera.rotation = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                    Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  camera.translation = Eigen::Vector3d(0.01, -0.02, 0.7);
  const double rotation[3] = {0.1, -0.2, 0.05}, translation[3] = {0.01, 0.02, -0.03};
  const double alpha[4] = {0.5, -1.0, 0.3, 2.0};
  const double beta[5] = {0.1, 0.9, 0.0, 0.5, 0.3};
  const double focal_scale[1] = {0.9};
  for (int landmark : {0, 30, 67}) {
    std::unique_ptr<ceres::CostFunction> cost(LandmarkReprojectionCost::Create(
        basis, landmark, camera, Eigen::Vector2d(255, 270), 0.7));
    ExpectGradientsMatch(cost.get(), {rotation, translation, alpha, beta, focal_scale});
    // The focal scale zooms and dollies the camera.
    const double* parameters[] = {rotation, translation, alpha, beta, focal_scale};
    double residual[2];
    ASSERT_TRUE(cost->Evaluate(parameters, residual, nullptr));
    const Eigen::VectorXd a = Eigen::Map<const Eigen::VectorXd>(alpha, 4), b = Eigen::Map<const Eigen::VectorXd>(beta, 5);
    Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
    const Eigen::Vector3d aa(rotation[0], rotation[1], rotation[2]);
    motion.linear() = Eigen::AngleAxisd(aa.norm(), aa.normalized()).toRotationMatrix();
    motion.translation() = Eigen::Vector3d(translation[0], translation[1], translation[2]);
    const Eigen::Vector2d expected =
        0.7 * (camera.WithFocalScale(0.9).Pixel(motion * basis.Point(landmark, a, b)) - Eigen::Vector2d(255, 270));
    EXPECT_NEAR(residual[0], expected.x(), 1e-9);
    EXPECT_NEAR(residual[1], expected.y(), 1e-9);
  }
}

TEST(TrackingCosts, LandmarkBehindTheCameraIsRejected) {
  const LandmarkBasis basis = RandomBasis(2, 2, 2);
  TrackingCamera camera;  // identity pose: the head frame is the camera frame
  camera.translation = Eigen::Vector3d(0, 0, -1.0);  // everything behind
  std::unique_ptr<ceres::CostFunction> cost(
      LandmarkReprojectionCost::Create(basis, 3, camera, Eigen::Vector2d(0, 0), 1.0));
  const double zero3[3] = {0, 0, 0}, alpha[2] = {0, 0}, beta[2] = {0, 0}, focal_scale[1] = {1};
  const double* parameters[] = {zero3, zero3, alpha, beta, focal_scale};
  double residual[2];
  EXPECT_FALSE(cost->Evaluate(parameters, residual, nullptr));
}

TEST(TrackingCosts, SmoothnessAndPriorGradients) {
  const double a[5] = {0.1, 0.2, 0.3, 0.4, 0.5}, b[5] = {0.5, 0.1, 0.0, 0.9, 0.2};
  std::unique_ptr<ceres::CostFunction> smooth(CoefficientSmoothnessCost::Create(5, 3.0));
  ExpectGradientsMatch(smooth.get(), {a, b});
  std::unique_ptr<ceres::CostFunction> prior(CoefficientPriorCost::Create(5, 2.0));
  ExpectGradientsMatch(prior.get(), {a});
  // And their values.
  const double* pair[] = {a, b};
  double r[5];
  ASSERT_TRUE(smooth->Evaluate(pair, r, nullptr));
  EXPECT_DOUBLE_EQ(r[3], 3.0 * (0.9 - 0.4));
  const double* one[] = {a};
  ASSERT_TRUE(prior->Evaluate(one, r, nullptr));
  EXPECT_DOUBLE_EQ(r[4], 1.0);
  // The pose smoothness shared with calibration.
  const double r0[3] = {0.1, 0.2, 0.3}, t0[3] = {1, 2, 3}, r1[3] = {0.2, 0.1, 0.0}, t1[3] = {0, 1, 5};
  std::unique_ptr<ceres::CostFunction> pose(PoseSmoothnessCost::Create(10.0, 100.0));
  ExpectGradientsMatch(pose.get(), {r0, t0, r1, t1});
}

}  // namespace
}  // namespace headforge
