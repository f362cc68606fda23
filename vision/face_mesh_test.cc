// The face mesh's region geometry (where the network looks and how its
// points come back to the image) and, with the model installed, the network
// on a real GRID face: found, laid out as a face, and carried along when the
// image turns and shrinks.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "vision/face_mesh.h"

namespace headforge {
namespace {

TEST(FaceRegion, TheNetworksInputIsTheTurnedSquareOfTheImage) {
  // A bright dot a quarter of the side along the region's turned +x axis
  // lands a quarter of the input right of its centre.
  cv::Mat image(400, 400, CV_8UC3, cv::Scalar::all(0));
  FaceRegion region;
  region.centre = cv::Point2d(210, 190);
  region.side = 160;
  region.angle = 30.0 * M_PI / 180.0;
  const cv::Point2d dot = region.centre + 40.0 * cv::Point2d(std::cos(region.angle), std::sin(region.angle));
  cv::circle(image, cv::Point(int(std::lround(dot.x)), int(std::lround(dot.y))), 3, cv::Scalar::all(255), cv::FILLED);
  const cv::Mat input = FaceMesh::Input(image, region);
  ASSERT_EQ(input.size(), cv::Size(FaceMesh::kInputSize, FaceMesh::kInputSize));
  ASSERT_EQ(input.type(), CV_32FC3);
  cv::Mat grey;
  cv::cvtColor(input, grey, cv::COLOR_RGB2GRAY);
  const cv::Moments m = cv::moments(grey);
  ASSERT_GT(m.m00, 0);
  // Position in the square: pixel i spans [i, i + 1].
  EXPECT_NEAR(m.m10 / m.m00 + 0.5, 96 + 48, 1.0);
  EXPECT_NEAR(m.m01 / m.m00 + 0.5, 96, 1.0);
}

TEST(FaceRegion, FromTheMeshIsMediaPipesSquare) {
  // Points on a 100 x 60 box turned by 10 degrees, eye corners level in the face.
  std::vector<cv::Point3f> points(kFaceMeshPoints, cv::Point3f(0, 0, 0));
  const double a = 10.0 * M_PI / 180.0;
  auto place = [&](int i, double x, double y) {
    points[i] = cv::Point3f(float(200 + x * std::cos(a) - y * std::sin(a)), float(150 + x * std::sin(a) + y * std::cos(a)), 0);
  };
  for (int i = 0; i < kFaceMeshPoints; ++i) place(i, (i % 2 ? 30 : -30), (i % 3 ? 50 : -50));
  place(33, -20, -10);
  place(263, 20, -10);
  const FaceRegion r = FaceRegionFromMesh(points);
  EXPECT_NEAR(r.angle, a, 1e-6);
  EXPECT_NEAR(r.centre.x, 200, 0.5);
  EXPECT_NEAR(r.centre.y, 150, 0.5);
  // The axis-aligned box of the turned 60 x 100 box, its longer side x 1.5.
  const double tall = 100 * std::cos(a) + 60 * std::sin(a);
  EXPECT_NEAR(r.side, 1.5 * tall, 0.5);
}

TEST(FaceMesh, AMissingModelNamesTheInstallStep) {
  std::unique_ptr<FaceMesh> mesh;
  const Status s = FaceMesh::Load("/nonexistent/models", &mesh);
  EXPECT_EQ(s.code(), Status::Code::kNotFound);
  EXPECT_NE(s.message().find("install_deps"), std::string::npos) << s.message();
  EXPECT_EQ(mesh, nullptr);
}

#ifdef HEADFORGE_HUMAN_MODELS
cv::Mat GridFrame() {
  cv::VideoCapture capture(std::string(HEADFORGE_TEST_SHARED_DATA) + "/video/grid/bbaf2n.mpg", cv::CAP_FFMPEG);
  cv::Mat frame;
  capture.read(frame);
  return frame;
}

TEST(FaceMeshNetwork, FindsARealFaceAndFollowsItWhenTheImageTurns) {
  std::unique_ptr<FaceMesh> mesh;
  const Status load = FaceMesh::Load(HEADFORGE_HUMAN_MODELS, &mesh);
  ASSERT_TRUE(load.ok()) << load.message();
  const cv::Mat frame = GridFrame();
  ASSERT_FALSE(frame.empty());
  // GRID's speaker fills the middle of the 360 x 288 frame.
  FaceRegion start;
  start.centre = cv::Point2d(frame.cols / 2.0, frame.rows / 2.0);
  start.side = 200;
  const FaceMeshResult found = mesh->Refine(frame, mesh->Refine(frame, start).region);
  EXPECT_GT(found.score, 0.9f);
  ASSERT_EQ(found.points.size(), size_t(kFaceMeshPoints));
  // A face's layout: the subject's right eye corner (33) left of the left
  // one (263), the nose tip (1) below the eyes, the chin (152) lowest, the
  // forehead (10) highest.
  const auto& p = found.points;
  EXPECT_LT(p[33].x, p[263].x);
  EXPECT_GT(p[1].y, p[33].y);
  EXPECT_GT(p[152].y, p[1].y);
  EXPECT_LT(p[10].y, p[33].y);
  const double face = cv::norm(cv::Point2f(p[152].x, p[152].y) - cv::Point2f(p[10].x, p[10].y));
  EXPECT_GT(face, 60);

  // The frame turned by 25 degrees and shrunk by 0.8 about its centre: the
  // points found there are the turned points, within 3 % of the face's
  // height (median over the 468).
  const cv::Point2f centre(frame.cols / 2.0f, frame.rows / 2.0f);
  const cv::Mat m = cv::getRotationMatrix2D(centre, -25.0, 0.8);  // OpenCV's angle: counter-clockwise
  cv::Mat turned;
  cv::warpAffine(frame, turned, m, frame.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  std::vector<cv::Point3f> moved;
  for (const cv::Point3f& q : p) {
    const double x = m.at<double>(0, 0) * q.x + m.at<double>(0, 1) * q.y + m.at<double>(0, 2);
    const double y = m.at<double>(1, 0) * q.x + m.at<double>(1, 1) * q.y + m.at<double>(1, 2);
    moved.emplace_back(float(x), float(y), q.z * 0.8f);
  }
  const FaceMeshResult again = mesh->Refine(turned, FaceRegionFromMesh(moved));
  EXPECT_GT(again.score, 0.9f);
  EXPECT_NEAR(again.region.angle, 25.0 * M_PI / 180.0, 4.0 * M_PI / 180.0);
  std::vector<double> errors;
  for (int i = 0; i < kFaceMeshPoints; ++i)
    errors.push_back(cv::norm(cv::Point2f(again.points[i].x - moved[i].x, again.points[i].y - moved[i].y)));
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.03 * face * 0.8) << "median " << errors[errors.size() / 2] << " px";
}

// Hard cases: where there is no face (noise, a plain wall) the network's
// face probability stays low, so ingest leaves the frame's mesh out and the
// 68 points carry on; a face at the edge of the frame (half of its square
// outside, black there) and a small one (40 px between brow and chin) are
// still found and laid out as a face, and every point comes back finite.
TEST(FaceMeshNetwork, HardCasesStayFiniteAndNoFaceIsRefused) {
  std::unique_ptr<FaceMesh> mesh;
  ASSERT_TRUE(FaceMesh::Load(HEADFORGE_HUMAN_MODELS, &mesh).ok());
  FaceRegion region;
  region.centre = cv::Point2d(150, 150);
  region.side = 200;
  cv::Mat noise(300, 300, CV_8UC3);
  cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(255));
  const cv::Mat wall(300, 300, CV_8UC3, cv::Scalar(170, 180, 190));
  for (const cv::Mat& image : {noise, wall}) {
    const FaceMeshResult r = mesh->Refine(image, region);
    EXPECT_LT(r.score, 0.5f);
    for (const cv::Point3f& p : r.points) EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
  }
  const cv::Mat frame = GridFrame();
  FaceRegion start;
  start.centre = cv::Point2d(frame.cols / 2.0, frame.rows / 2.0);
  start.side = 200;
  const FaceMeshResult found = mesh->Refine(frame, mesh->Refine(frame, start).region);
  ASSERT_GT(found.score, 0.9f);
  auto face_like = [](const FaceMeshResult& r) {
    const auto& p = r.points;
    return p[33].x < p[263].x && p[1].y > p[33].y && p[152].y > p[1].y && p[10].y < p[33].y;
  };
  // At the edge: the frame shifted so that the face's centre sits 20 px from the left.
  const double dx = 20 - found.region.centre.x;
  cv::Mat edge;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, dx, 0, 1, 0);
  cv::warpAffine(frame, edge, shift, frame.size());
  FaceRegion moved = found.region;
  moved.centre.x += dx;
  const FaceMeshResult at_edge = mesh->Refine(edge, moved);
  EXPECT_GT(at_edge.score, 0.5f);
  EXPECT_TRUE(face_like(at_edge));
  // Small: the frame shrunk until the face is about 40 px tall.
  const double face =
      cv::norm(cv::Point2f(found.points[152].x - found.points[10].x, found.points[152].y - found.points[10].y));
  const double scale = 40.0 / face;
  cv::Mat small;
  cv::resize(frame, small, cv::Size(), scale, scale, cv::INTER_AREA);
  FaceRegion shrunk = found.region;
  shrunk.centre *= scale;
  shrunk.side *= scale;
  const FaceMeshResult tiny = mesh->Refine(small, shrunk);
  std::printf("face probability: at the edge %.3f, 40 px tall %.3f\n", at_edge.score, tiny.score);
  for (const cv::Point3f& p : tiny.points) EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
  if (tiny.score >= 0.5f) EXPECT_TRUE(face_like(tiny));
}
#endif  // HEADFORGE_HUMAN_MODELS

}  // namespace
}  // namespace headforge
