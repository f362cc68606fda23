#include "core/mesh_renderer.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

namespace headforge {
namespace {

// A quad in the plane through `origin` spanned by `du`, `dv`, with UVs 0..1.
Mesh Quad(const Eigen::Vector3f& origin, const Eigen::Vector3f& du, const Eigen::Vector3f& dv,
          uint8_t part = kPartFace) {
  Material material;
  material.part = part;
  material.colour = Eigen::Vector3f(1, 1, 1);
  return MakeQuad(origin, du, dv, material);
}

PinholeCamera Camera(int size = 64) {
  PinholeCamera c;
  c.width = c.height = size;
  c.fx = c.fy = size;
  c.cx = c.cy = (size - 1) / 2.0;
  return c;
}

// Intersects the pixel's ray with a plane: returns depth z and the point.
Eigen::Vector3d RayPlane(const PinholeCamera& c, int x, int y, const Eigen::Vector3d& origin,
                         const Eigen::Vector3d& normal) {
  const Eigen::Vector3d ray((x - c.cx) / c.fx, (y - c.cy) / c.fy, 1.0);
  const double s = origin.dot(normal) / ray.dot(normal);
  return s * ray;
}

TEST(MeshRenderer, DepthUvAndNormalOfATiltedPlaneArePerspectiveCorrect) {
  // A plane tilted 60 degrees, from z = 1 to z = 3: affine interpolation would be far off.
  const Eigen::Vector3f origin(-1.0f, -0.8f, 1.0f), du(2.0f, 0.0f, 0.0f), dv(0.0f, 1.6f, 2.0f);
  const Mesh quad = Quad(origin, du, dv);
  const PinholeCamera camera = Camera();
  RenderOutput out;
  RenderMeshes({&quad}, camera, RenderOptions(), &out);
  const Eigen::Vector3d n = du.cast<double>().cross(dv.cast<double>()).normalized();
  int checked = 0;
  for (int y = 2; y < 62; y += 5) {
    for (int x = 2; x < 62; x += 5) {
      if (out.part.at<uint8_t>(y, x) != kPartFace) continue;
      const Eigen::Vector3d p = RayPlane(camera, x, y, origin.cast<double>(), n);
      EXPECT_NEAR(out.depth.at<float>(y, x), p.z(), 1e-4);
      // UV from the plane point: u along du, v along dv.
      const Eigen::Vector3d q = p - origin.cast<double>();
      const double u = q.dot(du.cast<double>()) / du.squaredNorm();
      const double v = q.dot(dv.cast<double>()) / dv.squaredNorm();
      EXPECT_NEAR(out.uv.at<cv::Vec2f>(y, x)[0], u, 1e-4);
      EXPECT_NEAR(out.uv.at<cv::Vec2f>(y, x)[1], v, 1e-4);
      const cv::Vec3f normal = out.normal.at<cv::Vec3f>(y, x);
      EXPECT_NEAR(std::abs(normal[0] * n.x() + normal[1] * n.y() + normal[2] * n.z()), 1.0, 1e-5);
      ++checked;
    }
  }
  EXPECT_GT(checked, 50);
}

TEST(MeshRenderer, NearerSurfaceWinsAndEdgesAreAntialiased) {
  const Mesh far = Quad({-1, -1, 2}, {2, 0, 0}, {0, 2, 0}, kPartHair);
  // A near quad covering the left half of the image (x < 0).
  Mesh near = Quad({-1, -1, 1}, {1, 0, 0}, {0, 2, 0}, kPartOccluder);
  RenderOptions options;
  options.supersample = 3;
  RenderOutput out;
  RenderMeshes({&far, &near}, Camera(), options, &out);
  EXPECT_EQ(out.part.at<uint8_t>(32, 10), kPartOccluder);
  EXPECT_NEAR(out.depth.at<float>(32, 10), 1.0f, 1e-5);
  EXPECT_EQ(out.part.at<uint8_t>(32, 50), kPartHair);
  EXPECT_NEAR(out.depth.at<float>(32, 50), 2.0f, 1e-5);
  // The occluder's edge x = 0 falls at pixel 31.5: columns 31 and 32 are split,
  // and the coverage of face/hair samples rises from 0 to 1 across them.
  EXPECT_FLOAT_EQ(out.coverage.at<float>(32, 20), 0.0f);
  EXPECT_FLOAT_EQ(out.coverage.at<float>(32, 40), 1.0f);
  const float edge = out.coverage.at<float>(32, 31) + out.coverage.at<float>(32, 32);
  EXPECT_GT(edge, 0.5f);
  EXPECT_LT(edge, 1.5f);
}

TEST(MeshRenderer, GeometryBehindTheCameraIsClippedAtTheNearPlane) {
  // A floor plane y = 0.5 running from behind the camera to far ahead.
  const Mesh floor = Quad({-5, 0.5f, -5}, {10, 0, 0}, {0, 0, 20});
  const PinholeCamera camera = Camera();
  RenderOutput out;
  RenderMeshes({&floor}, camera, RenderOptions(), &out);
  // Rows below the horizon see the floor at the analytic depth; rows above see nothing.
  for (int y = 40; y < 64; y += 4) {
    const Eigen::Vector3d p = RayPlane(camera, 32, y, {0, 0.5, 0}, {0, 1, 0});
    EXPECT_NEAR(out.depth.at<float>(y, 32), p.z(), 1e-3 * p.z()) << y;
  }
  EXPECT_EQ(out.part.at<uint8_t>(10, 32), kPartBackground);
  EXPECT_EQ(out.triangle.at<int>(10, 32), -1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) EXPECT_TRUE(std::isfinite(out.depth.at<float>(y, x)));
}

TEST(MeshRenderer, ProjectAgreesWithTheRasterisedVertex) {
  // A tiny triangle around a known point lands on the pixel Project() names.
  const Eigen::Vector3f p(0.13f, -0.07f, 1.5f);
  Mesh m;
  m.vertices.resize(3, 3);
  m.vertices << p + Eigen::Vector3f(-0.004f, -0.004f, 0), p + Eigen::Vector3f(0.004f, -0.004f, 0),
      p + Eigen::Vector3f(0, 0.004f, 0);
  m.triangles.resize(3, 1);
  m.triangles << 0, 1, 2;
  m.materials = {Material()};
  PinholeCamera camera = Camera(128);
  camera.cam_from_world = LookAt({0.3, 0.2, -0.5}, {0.1, -0.05, 1.5});
  RenderOutput out;
  RenderMeshes({&m}, camera, RenderOptions(), &out);
  cv::Moments mom = cv::moments(out.coverage, false);
  ASSERT_GT(mom.m00, 0);
  const Eigen::Vector2d centroid = camera.Project(((m.vertices.col(0) + m.vertices.col(1) + m.vertices.col(2)) / 3).cast<double>());
  // The triangle's pixel centroid matches its projected centroid (to a pixel: the
  // projected centroid of a triangle differs slightly from the centroid's projection).
  EXPECT_NEAR(mom.m10 / mom.m00, centroid.x(), 0.5);
  EXPECT_NEAR(mom.m01 / mom.m00, centroid.y(), 0.5);
}

TEST(MeshRenderer, LookAtPutsTheTargetAtThePrincipalPointWithYUp) {
  PinholeCamera camera = Camera(100);
  camera.cam_from_world = LookAt({2, 1, 3}, {0, 0.2, 0});
  const Eigen::Vector2d target = camera.Project({0, 0.2, 0});
  EXPECT_NEAR(target.x(), camera.cx, 1e-9);
  EXPECT_NEAR(target.y(), camera.cy, 1e-9);
  // World +y appears upward (smaller row).
  EXPECT_LT(camera.Project({0, 0.5, 0}).y(), target.y());
}

TEST(MeshRenderer, TextureSamplingIsBilinearAndRepeats) {
  Texture t;
  t.image = cv::Mat(2, 2, CV_32FC3);
  t.image.at<cv::Vec3f>(0, 0) = {0, 0, 0};  // top-left (v = 1)
  t.image.at<cv::Vec3f>(0, 1) = {1, 1, 1};
  t.image.at<cv::Vec3f>(1, 0) = {0, 0, 0};
  t.image.at<cv::Vec3f>(1, 1) = {1, 1, 1};
  EXPECT_NEAR(t.Sample(0.25f, 0.5f).x(), 0.0f, 1e-6);
  EXPECT_NEAR(t.Sample(0.75f, 0.5f).x(), 1.0f, 1e-6);
  EXPECT_NEAR(t.Sample(0.5f, 0.5f).x(), 0.5f, 1e-6);
  EXPECT_NEAR(t.Sample(1.75f, 0.5f).x(), 1.0f, 1e-6);
}

}  // namespace
}  // namespace headforge
