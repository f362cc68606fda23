// Hard cases of the geometric solvers stay numerically stable: each returns a
// finite result with a quality flag, or a clear failure; never a silent NaN.
// Random cases come from rapidcheck (shrunk to a minimal failing case).
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>
#include <rapidcheck/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "calibration/pnp.h"
#include "calibration/reprojection_cost.h"
#include "calibration/similarity.h"
#include "calibration/triangulation.h"

namespace headforge {
namespace {

double RotationAngle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

Eigen::Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  return Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized().toRotationMatrix();
}

Eigen::Matrix3Xd RandomPoints(std::mt19937_64& rng, int count, double spread) {
  std::normal_distribution<double> n(0.0, spread);
  Eigen::Matrix3Xd p(3, count);
  for (int i = 0; i < count; ++i) p.col(i) = Eigen::Vector3d(n(rng), n(rng), n(rng));
  return p;
}

Eigen::Matrix3Xd Apply(const Sim3& t, const Eigen::Matrix3Xd& p) {
  Eigen::Matrix3Xd out(3, p.cols());
  for (int i = 0; i < p.cols(); ++i) out.col(i) = t * p.col(i);
  return out;
}

void ExpectFinite(const SimilarityResult& r) {
  EXPECT_TRUE(std::isfinite(r.tgt_from_src.scale));
  EXPECT_TRUE(r.tgt_from_src.rotation.allFinite());
  EXPECT_TRUE(r.tgt_from_src.translation.allFinite());
  EXPECT_TRUE(std::isfinite(r.rms));
}

// Exact correspondences at any scale from 1e-6 to 1e6 are recovered exactly.
RC_GTEST_PROP(Similarity, RecoversExactTransformsAtAnyScale, ()) {
  const uint64_t seed = *rc::gen::arbitrary<uint64_t>();
  const int count = *rc::gen::inRange(3, 60);
  const int scale_exp = *rc::gen::inRange(-6, 7);     // source extent 10^e
  const int factor_exp = *rc::gen::inRange(-6, 7);    // similarity scale 10^f
  std::mt19937_64 rng(seed);
  const double extent = std::pow(10.0, scale_exp);
  const Eigen::Matrix3Xd src = RandomPoints(rng, count, extent);
  Sim3 truth;
  truth.scale = std::pow(10.0, factor_exp);
  truth.rotation = RandomRotation(rng);
  truth.translation = RandomPoints(rng, 1, truth.scale * extent * 10).col(0);
  const SimilarityResult r = EstimateSimilarity(src, Apply(truth, src));
  ExpectFinite(r);
  RC_ASSERT(r.ok);
  RC_ASSERT(std::abs(r.tgt_from_src.scale / truth.scale - 1.0) < 1e-8);
  RC_ASSERT(RotationAngle(r.tgt_from_src.rotation, truth.rotation) < 1e-7);
  RC_ASSERT((r.tgt_from_src.translation - truth.translation).norm() < 1e-7 * truth.scale * extent * 20);
}

TEST(Similarity, ThreePointsAreEnough) {
  Eigen::Matrix3Xd src(3, 3);
  src << 0, 1, 0, 0, 0, 1, 0, 0, 0;
  Sim3 truth;
  truth.scale = 2.5;
  truth.rotation = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  truth.translation = Eigen::Vector3d(1, -2, 3);
  const SimilarityResult r = EstimateSimilarity(src, Apply(truth, src));
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.quality, SimilarityQuality::kPlanar);  // three points are always coplanar
  EXPECT_NEAR(r.tgt_from_src.scale, 2.5, 1e-12);
  EXPECT_LT(RotationAngle(r.tgt_from_src.rotation, truth.rotation), 1e-10);
  EXPECT_LT(r.rms, 1e-12);
}

TEST(Similarity, TooFewCollinearAndCoincidentPointsAreDegenerate) {
  Eigen::Matrix3Xd two(3, 2);
  two << 0, 1, 0, 0, 0, 0;
  SimilarityResult r = EstimateSimilarity(two, two);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.quality, SimilarityQuality::kDegenerate);
  ExpectFinite(r);

  Eigen::Matrix3Xd line(3, 5);
  for (int i = 0; i < 5; ++i) line.col(i) = Eigen::Vector3d(1, 2, 3) * i + Eigen::Vector3d(0.5, 0, 0);
  r = EstimateSimilarity(line, line * 2.0);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("collinear"), std::string::npos);
  ExpectFinite(r);

  const Eigen::Matrix3Xd same = Eigen::Vector3d(1, 1, 1).replicate(1, 6);
  r = EstimateSimilarity(same, same);
  EXPECT_FALSE(r.ok);
  ExpectFinite(r);

  std::mt19937_64 rng(1);
  Eigen::Matrix3Xd with_nan = RandomPoints(rng, 5, 1.0);
  with_nan(1, 2) = std::nan("");
  r = EstimateSimilarity(with_nan, with_nan);
  EXPECT_FALSE(r.ok);
  ExpectFinite(r);
}

TEST(Similarity, CoplanarPointsAreSolvedAndFlagged) {
  std::mt19937_64 rng(3);
  Eigen::Matrix3Xd src = RandomPoints(rng, 20, 1.0);
  src.row(2).setZero();
  Sim3 truth;
  truth.scale = 0.3;
  truth.rotation = RandomRotation(rng);
  truth.translation = Eigen::Vector3d(0.1, 0.2, 0.3);
  const SimilarityResult r = EstimateSimilarity(src, Apply(truth, src));
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.quality, SimilarityQuality::kPlanar);
  EXPECT_LT(RotationAngle(r.tgt_from_src.rotation, truth.rotation), 1e-9);
}

TEST(Similarity, MirrorImagesAreFlaggedNotReturnedAsRotations) {
  std::mt19937_64 rng(4);
  const Eigen::Matrix3Xd src = RandomPoints(rng, 30, 1.0);
  Eigen::Matrix3Xd tgt = src;
  tgt.row(0) *= -1.0;  // a mirror, not a rotation
  const SimilarityResult r = EstimateSimilarity(src, tgt);
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.quality, SimilarityQuality::kReflection);
  EXPECT_NEAR(r.tgt_from_src.rotation.determinant(), 1.0, 1e-9);
  EXPECT_GT(r.rms, 0.1);  // a rotation cannot explain a mirror image
  ExpectFinite(r);
}

TEST(Similarity, DuplicatePointsAmongOthersDoNotHurt) {
  std::mt19937_64 rng(5);
  Eigen::Matrix3Xd src = RandomPoints(rng, 10, 1.0);
  src.col(3) = src.col(2);
  src.col(7) = src.col(2);
  Sim3 truth;
  truth.scale = 4.0;
  truth.rotation = RandomRotation(rng);
  const SimilarityResult r = EstimateSimilarity(src, Apply(truth, src));
  ASSERT_TRUE(r.ok);
  EXPECT_NEAR(r.tgt_from_src.scale, 4.0, 1e-9);
}

// Up to half the pairs are gross outliers; RANSAC finds the inliers and the
// transform to the noise level.
RC_GTEST_PROP(Similarity, RansacToleratesHalfOutliers, ()) {
  const uint64_t seed = *rc::gen::arbitrary<uint64_t>();
  const int inliers = *rc::gen::inRange(8, 40);
  const int outliers = *rc::gen::inRange(0, inliers + 1);  // at most 50%
  std::mt19937_64 rng(seed);
  const Eigen::Matrix3Xd clean = RandomPoints(rng, inliers, 0.05);  // a head-sized cloud, metres
  Sim3 truth;
  truth.scale = 1.0 + 0.5 * std::uniform_real_distribution<double>(-1, 1)(rng);
  truth.rotation = RandomRotation(rng);
  truth.translation = RandomPoints(rng, 1, 0.5).col(0);
  Eigen::Matrix3Xd src(3, inliers + outliers), tgt(3, inliers + outliers);
  src.leftCols(inliers) = clean;
  tgt.leftCols(inliers) = Apply(truth, clean) + RandomPoints(rng, inliers, 0.0005);  // 0.5 mm noise
  src.rightCols(outliers) = RandomPoints(rng, outliers, 0.05);
  tgt.rightCols(outliers) = RandomPoints(rng, outliers, 0.3);
  RansacOptions options;
  options.inlier_threshold = 0.004;
  options.seed = seed;
  const SimilarityResult r = EstimateSimilarityRansac(src, tgt, options);
  ExpectFinite(r);
  RC_ASSERT(r.ok);
  RC_ASSERT(std::abs(r.tgt_from_src.scale / truth.scale - 1.0) < 0.05);
  RC_ASSERT(RotationAngle(r.tgt_from_src.rotation, truth.rotation) < 0.1);
  RC_ASSERT(static_cast<int>(r.inliers.size()) >= inliers - 2);
}

Eigen::Matrix<double, 3, 4> Projection(const Eigen::Matrix3d& k, const Eigen::Isometry3d& cam_from_world) {
  return k * cam_from_world.matrix().topRows<3>();
}

Eigen::Isometry3d LookingAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitY());
  if (x.norm() < 1e-6) x = z.cross(Eigen::Vector3d::UnitX());
  x.normalize();
  Eigen::Matrix3d r;
  r << x, z.cross(x), z;
  Eigen::Isometry3d world_from_cam = Eigen::Isometry3d::Identity();
  world_from_cam.linear() = r;
  world_from_cam.translation() = eye;
  return world_from_cam.inverse();
}

const Eigen::Matrix3d kK = (Eigen::Matrix3d() << 800, 0, 320, 0, 800, 240, 0, 0, 1).finished();

RC_GTEST_PROP(Triangulation, RecoversExactPointsFromTwoToEightViews, ()) {
  const uint64_t seed = *rc::gen::arbitrary<uint64_t>();
  const int count = *rc::gen::inRange(2, 9);
  std::mt19937_64 rng(seed);
  const Eigen::Vector3d point = RandomPoints(rng, 1, 0.1).col(0);
  std::vector<TriangulationView> views;
  for (int i = 0; i < count; ++i) {
    const double az = (i - (count - 1) / 2.0) * 0.3;
    const Eigen::Vector3d eye(std::sin(az), 0.1 * i, std::cos(az));
    TriangulationView v;
    v.projection = Projection(kK, LookingAt(eye, Eigen::Vector3d::Zero()));
    const Eigen::Vector3d h = v.projection * point.homogeneous();
    v.pixel = h.head<2>() / h.z();
    views.push_back(v);
  }
  const TriangulationResult r = TriangulatePoint(views);
  RC_ASSERT(r.ok);
  RC_ASSERT(r.point.allFinite());
  RC_ASSERT((r.point - point).norm() < 1e-7);
}

TEST(Triangulation, NearlyParallelRaysAreFlaggedAndFinite) {
  const Eigen::Vector3d point(0.0, 0.0, 10.0);
  std::vector<TriangulationView> views;
  for (double baseline : {0.0, 1e-3}) {
    TriangulationView v;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(-baseline, 0, 0);
    v.projection = Projection(kK, pose);
    const Eigen::Vector3d h = v.projection * point.homogeneous();
    v.pixel = h.head<2>() / h.z() + Eigen::Vector2d(0.05, 0.0);  // a little noise
    views.push_back(v);
  }
  const TriangulationResult r = TriangulatePoint(views);
  EXPECT_TRUE(r.point.allFinite());
  EXPECT_TRUE(std::isfinite(r.max_angle_deg));
  if (r.ok) {
    EXPECT_EQ(r.quality, TriangulationQuality::kLowParallax);
    EXPECT_LT(r.max_angle_deg, 0.01);
  } else {
    EXPECT_FALSE(r.message.empty());
  }
}

TEST(Triangulation, ParallelRaysAndPointsBehindFailClearly) {
  // Two cameras side by side seeing a point straight ahead at their own
  // principal points: the rays are exactly parallel.
  std::vector<TriangulationView> views;
  for (double x : {0.0, 0.2}) {
    TriangulationView v;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(-x, 0, 0);
    v.projection = Projection(kK, pose);
    v.pixel = Eigen::Vector2d(320, 240);
    views.push_back(v);
  }
  TriangulationResult r = TriangulatePoint(views);
  EXPECT_FALSE(r.ok);
  EXPECT_FALSE(r.message.empty());
  EXPECT_TRUE(r.point.allFinite());
  // A point behind both cameras.
  const Eigen::Vector3d behind(0.1, 0.0, -2.0);
  for (auto& v : views) {
    const Eigen::Vector3d h = v.projection * behind.homogeneous();
    v.pixel = h.head<2>() / h.z();
  }
  r = TriangulatePoint(views);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("behind"), std::string::npos) << r.message;
  EXPECT_EQ(TriangulatePoint({views[0]}).ok, false);
}

std::vector<Eigen::Vector2d> ProjectAll(const std::vector<Eigen::Vector3d>& points, const Eigen::Isometry3d& pose) {
  std::vector<Eigen::Vector2d> pixels;
  for (const auto& p : points) {
    const Eigen::Vector3d h = kK * (pose * p);
    pixels.push_back(h.head<2>() / h.z());
  }
  return pixels;
}

RC_GTEST_PROP(Pnp, RecoversExactPoses, ()) {
  std::mt19937_64 rng(*rc::gen::arbitrary<uint64_t>());
  const int count = *rc::gen::inRange(6, 70);
  const Eigen::Matrix3Xd cloud = RandomPoints(rng, count, 0.06);
  std::vector<Eigen::Vector3d> object;
  for (int i = 0; i < count; ++i) object.push_back(cloud.col(i));
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.5 * std::uniform_real_distribution<double>(-1, 1)(rng),
                                    RandomPoints(rng, 1, 1.0).col(0).normalized())
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(0.02, -0.01, 0.6);
  const PnpResult r = SolvePnp(object, ProjectAll(object, pose), kK);
  RC_ASSERT(r.ok);
  RC_ASSERT(RotationAngle(r.cam_from_object.linear(), pose.linear()) < 1e-6);
  RC_ASSERT((r.cam_from_object.translation() - pose.translation()).norm() < 1e-6);
}

TEST(Pnp, LandmarksCloseToALineAreFlaggedOrRefused) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> along(-0.05, 0.05), across(-1e-4, 1e-4);
  std::vector<Eigen::Vector3d> near_line, on_line;
  for (int i = 0; i < 20; ++i) {
    const double s = along(rng);
    near_line.emplace_back(s, 0.3 * s + across(rng), across(rng));
    on_line.emplace_back(s, 0.3 * s, 0.0);
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0, 0, 0.5);
  const PnpResult near = SolvePnp(near_line, ProjectAll(near_line, pose), kK);
  EXPECT_TRUE(near.cam_from_object.matrix().allFinite());
  if (near.ok) EXPECT_EQ(near.quality, PnpQuality::kNearlyDegenerate);
  else EXPECT_FALSE(near.message.empty());
  const PnpResult on = SolvePnp(on_line, ProjectAll(on_line, pose), kK);
  EXPECT_FALSE(on.ok);
  EXPECT_NE(on.message.find("collinear"), std::string::npos);
  EXPECT_TRUE(on.cam_from_object.matrix().allFinite());
  EXPECT_FALSE(SolvePnp({}, {}, kK).ok);
}

// The align refinement's cost: its derivatives against numeric differentiation.
TEST(AlignCosts, SimilarityReprojectionGradients) {
  Eigen::Matrix<double, 3, 4> projection;
  projection << 800, 3, 250, 40, -2, 810, 260, -30, 0.01, -0.02, 1, 2.5;
  const double world_from_head[7] = {0.3, -0.2, 0.1, 0.05, -0.1, 0.2, std::log(2.7)};
  for (const Eigen::Vector3d& point : {Eigen::Vector3d(0.03, 0.05, 0.1), Eigen::Vector3d(-0.07, -0.02, 0.01)}) {
    std::unique_ptr<ceres::CostFunction> cost(
        SimilarityReprojectionCost::Create(point, projection, Eigen::Vector2d(300, 240), 0.8));
    ceres::NumericDiffOptions numeric;
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
    ceres::GradientChecker checker(cost.get(), no_manifolds, numeric);
    ceres::GradientChecker::ProbeResults results;
    const double* parameters[] = {world_from_head};
    EXPECT_TRUE(checker.Probe(parameters, 1e-7, &results)) << results.error_log;
  }
  // The residual is zero where the pixel is the point's projection through
  // x_world = exp(log_s) R(w) x_head + t, and a point behind the camera is refused.
  const Eigen::Vector3d point(0.03, 0.05, 0.1);
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(world_from_head, ceres::ColumnMajorAdapter3x3(r.data()));
  const Eigen::Vector3d world =
      std::exp(world_from_head[6]) * (r * point) + Eigen::Vector3d(world_from_head[3], world_from_head[4], world_from_head[5]);
  const Eigen::Vector3d h = projection * world.homogeneous();
  std::unique_ptr<ceres::CostFunction> exact(
      SimilarityReprojectionCost::Create(point, projection, h.head<2>() / h.z(), 1.0));
  const double* parameters[] = {world_from_head};
  double residual[2];
  ASSERT_TRUE(exact->Evaluate(parameters, residual, nullptr));
  EXPECT_NEAR(residual[0], 0.0, 1e-9);
  EXPECT_NEAR(residual[1], 0.0, 1e-9);
  Eigen::Matrix<double, 3, 4> behind = projection;
  behind.row(2) *= -1;
  std::unique_ptr<ceres::CostFunction> refused(
      SimilarityReprojectionCost::Create(point, behind, Eigen::Vector2d(300, 240), 1.0));
  EXPECT_FALSE(refused->Evaluate(parameters, residual, nullptr));
}

}  // namespace
}  // namespace headforge
