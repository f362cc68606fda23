// Head-pose cameras on synthetic landmarks (the face model's landmark points
// projected through a known camera, with noise): a head that turns fixes the
// focal length, and the prior toward ordinary lenses leaves it alone; a head
// that holds still tells it less, which the reported uncertainty says, and
// the prior then moves it toward an ordinary lens. (The free identity of the
// face-model refinement loosens it far more: tracker_test.)
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "calibration/head_pose.h"
#include "core/face_model.h"

namespace headforge {
namespace {

constexpr double kPi = 3.14159265358979323846;

const FaceModel& Model() {
  static FaceModel model;
  static const bool loaded = [] {
    return FaceModel::Load(std::string(HEADFORGE_TEST_SHARED_DATA) + "/ict_facekit/ict_face_model.h5", &model).ok();
  }();
  EXPECT_TRUE(loaded);
  return model;
}

// 60 frames of the model's 68 landmark points seen by a 512-pixel camera of
// focal `focal` at `distance` metres, the head turning by up to `turn_deg`
// (yaw; half of it in pitch), with Gaussian noise of 1 px (a landmark
// detector's on a sharp face).
std::vector<std::optional<Landmarks68>> Landmarks(double focal, double distance, double turn_deg) {
  std::vector<Eigen::Vector3d> points;
  for (int v : Model().landmarks_ibug68()) points.push_back(Model().neutral().col(v).cast<double>());
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<std::optional<Landmarks68>> frames;
  for (int f = 0; f < 60; ++f) {
    const double yaw = turn_deg * std::sin(2 * kPi * f / 60) * kPi / 180;
    const double pitch = 0.5 * turn_deg * std::sin(4 * kPi * f / 60) * kPi / 180;
    // The camera looks down -z of the head frame's +z face: rotate 180 deg about y.
    const Eigen::Matrix3d r = (Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX())).toRotationMatrix();
    Landmarks68 l;
    for (int i = 0; i < 68; ++i) {
      Eigen::Vector3d p = r * points[size_t(i)];
      p.x() = -p.x();  // OpenCV camera: x right, y down, z forward
      p.y() = -p.y();
      p.z() += distance;
      l[size_t(i)] = cv::Point2f(float(focal * p.x() / p.z() + 255.5 + noise(rng)),
                                 float(focal * p.y() / p.z() + 255.5 + noise(rng)));
    }
    frames.push_back(l);
  }
  return frames;
}

HeadPoseResult Estimate(const std::vector<std::optional<Landmarks68>>& landmarks, double prior_sigma) {
  HeadPoseOptions options;
  options.prior_sigma = prior_sigma;
  options.prior_focal = FocalFromFov(options.prior_fov_deg, 512, 1.0);  // 443 px
  HeadPoseResult result;
  const Status s = EstimateHeadPoseCameras(Model(), landmarks, 512, 512, Eigen::Vector2d(255.5, 255.5), options, &result);
  EXPECT_TRUE(s.ok()) << s.message();
  return result;
}

TEST(HeadPoseFocal, ATurningHeadFixesTheFocalLengthAndThePriorLeavesItAlone) {
  const auto landmarks = Landmarks(1100, 0.65, 25);
  const HeadPoseResult with = Estimate(landmarks, 0.7), without = Estimate(landmarks, 0);
  std::printf("turning head: focal %.1f px (+-%.1f%%), %.1f px without the prior\n", with.focal,
              100 * with.focal_log_sigma, without.focal);
  EXPECT_NEAR(with.focal / 1100, 1.0, 0.03);
  EXPECT_NEAR(with.focal / without.focal, 1.0, 0.01);
  EXPECT_GT(with.focal_log_sigma, 0.0);
  EXPECT_LT(with.focal_log_sigma, 0.05);
}

TEST(HeadPoseFocal, AStillHeadLeavesItLooseAndThePriorPullsIt) {
  // A long lens far away (a broadcast close-up): perspective across the face
  // is a fraction of a pixel, so the landmarks barely tell the focal length.
  const auto still = Landmarks(4000, 2.5, 0.5), turning = Landmarks(1100, 0.65, 25);
  const HeadPoseResult with = Estimate(still, 0.7), without = Estimate(still, 0), turned = Estimate(turning, 0.7);
  std::printf("still head: focal %.1f px (+-%.1f%%) with the prior, %.1f px (+-%.1f%%) without\n", with.focal,
              100 * with.focal_log_sigma, without.focal, 100 * without.focal_log_sigma);
  // The reported uncertainty says how much less the video tells (measured:
  // 14 % against 2 %) ...
  EXPECT_GT(without.focal_log_sigma, 4 * turned.focal_log_sigma);
  EXPECT_GT(with.focal_log_sigma, 4 * turned.focal_log_sigma);
  // ... and the prior moves the estimate toward an ordinary lens (443 px), and only so far.
  EXPECT_LT(with.focal, without.focal);
  EXPECT_GT(with.focal, 0.8 * without.focal);
}

}  // namespace
}  // namespace headforge
