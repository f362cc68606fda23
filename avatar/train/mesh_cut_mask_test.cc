// MeshCutMask (dataset.h) on a sphere of 10 cm seen from 1 m: the ingested
// mask is kept within the silhouette grown by the skin's margin at the sides
// and below and by the hair's over the top, and nothing is added to it. The
// sphere's silhouette radius is f r / sqrt(d^2 - r^2) pixels.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "avatar/train/dataset.h"
#include "avatar/train/view_camera.h"

namespace headforge {
namespace {

constexpr double kRadius = 0.1, kDistance = 1.0, kFocal = 500;
constexpr int kSide = 160;

// A UV sphere of kRadius round the origin, its triangles wound outward:
// vertices [V, 3] float, triangles [T, 3] int64.
void Sphere(torch::Tensor* vertices, torch::Tensor* triangles) {
  const int rings = 48, segments = 96;
  std::vector<float> v;
  for (int i = 0; i <= rings; ++i) {
    const double polar = M_PI * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double azimuth = 2 * M_PI * j / segments;
      v.insert(v.end(), {float(kRadius * std::sin(polar) * std::cos(azimuth)), float(kRadius * std::cos(polar)),
                         float(kRadius * std::sin(polar) * std::sin(azimuth))});
    }
  }
  std::vector<int64_t> t;
  const auto at = [&](int i, int j) { return int64_t(i * segments + j % segments); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const int64_t a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
      for (const auto& tri : {std::array<int64_t, 3>{a, b, c}, std::array<int64_t, 3>{a, c, d}}) {
        // Wound so that the normal points away from the centre.
        const Eigen::Vector3f p0(&v[3 * tri[0]]), p1(&v[3 * tri[1]]), p2(&v[3 * tri[2]]);
        const bool outward = (p1 - p0).cross(p2 - p0).dot(p0 + p1 + p2) > 0;
        t.insert(t.end(), {tri[0], outward ? tri[1] : tri[2], outward ? tri[2] : tri[1]});
      }
    }
  *vertices = torch::from_blob(v.data(), {int64_t(v.size() / 3), 3}).clone();
  *triangles = torch::from_blob(t.data(), {int64_t(t.size() / 3), 3}, torch::kInt64).clone();
}

// Looking at the sphere from kDistance with the head frame's +y up in the image.
SplatCamera Camera() {
  SplatCamera camera;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  pose.translation() = Eigen::Vector3d(0, 0, kDistance);
  SetCameraPose(pose, &camera);
  camera.fx = camera.fy = kFocal;
  camera.cx = camera.cy = (kSide - 1) / 2.0;
  camera.width = camera.height = kSide;
  return camera;
}

class MeshCutMaskTest : public ::testing::Test {
 protected:
  void SetUp() override { Sphere(&vertices_, &triangles_); }
  cv::Mat Cut(const cv::Mat& mask, double hair) const {
    return MeshCutMask(mask, vertices_, vertices_, triangles_, Camera(), hair, 0.004);
  }
  // Pixel rows and columns `beyond` pixels past the silhouette's edge, from the centre.
  static int Past(double beyond) {
    const double edge = kFocal * kRadius / std::sqrt(kDistance * kDistance - kRadius * kRadius);
    return int(std::lround(edge + beyond));
  }
  torch::Tensor vertices_, triangles_;
};

TEST_F(MeshCutMaskTest, KeepsTheMaskNearTheHeadAndHairRoomOverTheTop) {
  const cv::Mat all(kSide, kSide, CV_8U, cv::Scalar(255));
  const cv::Mat cut = Cut(all, 0.03);
  const int c = kSide / 2;
  EXPECT_EQ(cut.at<uint8_t>(c, c), 255);
  // The skin's 4 mm is 2 px at 1 m: one pixel past the edge at the side and
  // below is kept, five are not.
  EXPECT_EQ(cut.at<uint8_t>(c, c + Past(1)), 255);
  EXPECT_EQ(cut.at<uint8_t>(c, c + Past(5)), 0);
  EXPECT_EQ(cut.at<uint8_t>(c, c - Past(5)), 0);
  EXPECT_EQ(cut.at<uint8_t>(c + Past(1), c), 255);
  EXPECT_EQ(cut.at<uint8_t>(c + Past(5), c), 0);
  // Over the top the hair's 3 cm (15 px): ten pixels up is kept, twenty not.
  EXPECT_EQ(cut.at<uint8_t>(c - Past(10), c), 255);
  EXPECT_EQ(cut.at<uint8_t>(c - Past(20), c), 0);
  // The area: more than the disc grown by the skin's 2 px, less than that
  // with its upper half grown by the hair's 15 px.
  const double area = cv::countNonZero(cut), skin = M_PI * Past(2) * Past(2);
  EXPECT_GT(area, skin);
  EXPECT_LT(area, skin + M_PI / 2 * (Past(15) * Past(15) - Past(0) * Past(0)));

  // Without hair room the top is cut like the sides.
  const cv::Mat bald = Cut(all, 0);
  EXPECT_EQ(bald.at<uint8_t>(c - Past(5), c), 0);
  EXPECT_EQ(bald.at<uint8_t>(c - Past(1), c), 255);
}

TEST_F(MeshCutMaskTest, AddsNothingToTheMask) {
  const int c = kSide / 2;
  EXPECT_EQ(cv::countNonZero(Cut(cv::Mat(kSide, kSide, CV_8U, cv::Scalar(0)), 0.03)), 0);
  // Half of the head masked: the other half stays out.
  cv::Mat left(kSide, kSide, CV_8U, cv::Scalar(0));
  left.colRange(0, c).setTo(255);
  const cv::Mat cut = Cut(left, 0.03);
  EXPECT_EQ(cut.at<uint8_t>(c, c - 10), 255);
  EXPECT_EQ(cv::countNonZero(cut.colRange(c, kSide)), 0);
}

}  // namespace
}  // namespace headforge
