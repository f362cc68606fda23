#include "calibration/face_points.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/triangulation.h"
#include "core/log.h"

namespace headforge {
namespace {

struct FaceView {
  int frame = 0;
  Eigen::Matrix<double, 3, 4> projection;  // K [R | t], distortion-free pixels
  Eigen::Vector3d axis;                    // optical axis, world frame
  std::vector<Eigen::Vector2d> pixels;     // features, distortion removed
  cv::Mat descriptors;
};

}  // namespace

Status TriangulateFacePoints(const IngestedCapture& capture, const CameraSet& cameras, const std::string& camera,
                             const FacePointOptions& options, std::vector<Eigen::Vector3d>* points,
                             FacePointStats* stats) {
  if (cameras.FindCamera(camera) == nullptr) return Status::NotFound("face points: no intrinsics for camera " + camera);
  const IngestedCamera* ingested = capture.FindCamera(camera);
  if (ingested == nullptr) return Status::NotFound("face points: camera " + camera + " was not ingested");
  std::vector<FaceViewRef> refs;
  for (const IngestedFrame& frame : ingested->frames) refs.push_back({camera, frame.index});
  return TriangulateFacePoints(capture, cameras, refs, options, points, stats);
}

Status TriangulateFacePoints(const IngestedCapture& capture, const CameraSet& cameras,
                             const std::vector<FaceViewRef>& refs, const FacePointOptions& options,
                             std::vector<Eigen::Vector3d>* points, FacePointStats* stats) {
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(0, 3, options.contrast_threshold);
  std::vector<FaceView> views;
  for (const FaceViewRef& ref : refs) {
    const CameraIntrinsics* intrinsics = cameras.FindCamera(ref.camera);
    const IngestedFrame* frame = capture.FindFrame(ref.camera, ref.frame);
    const CameraView* view = cameras.FindView(ref.camera, ref.frame);
    if (intrinsics == nullptr || frame == nullptr || view == nullptr || !view->registered || !frame->landmarks)
      continue;
    const fs::path path = capture.FramePath(ref.camera, ref.frame);
    const cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (image.empty()) return Status::IoError("face points: cannot read " + path.string());
    FaceView v;
    v.frame = ref.frame;
    v.projection = intrinsics->K() * view->cam_from_world.matrix().topRows<3>();
    v.axis = view->cam_from_world.rotation().transpose() * Eigen::Vector3d::UnitZ();
    std::vector<cv::KeyPoint> keypoints;
    sift->detectAndCompute(image, LandmarkHullMask(*frame->landmarks, image.size(), 1.0, options.margin_px), keypoints,
                           v.descriptors);
    for (const cv::KeyPoint& p : keypoints) v.pixels.push_back(intrinsics->Undistort(Eigen::Vector2d(p.pt.x, p.pt.y)));
    views.push_back(std::move(v));
  }

  // Each view's partners: the nearest viewing directions within the limits.
  const double min_cos = std::cos(options.max_angle_deg * M_PI / 180.0);
  const double max_cos = std::cos(options.min_angle_deg * M_PI / 180.0);
  std::set<std::pair<int, int>> pairs;
  for (int i = 0; i < static_cast<int>(views.size()); ++i) {
    std::vector<std::pair<double, int>> near;
    for (int j = 0; j < static_cast<int>(views.size()); ++j) {
      const double c = views[size_t(i)].axis.dot(views[size_t(j)].axis);
      if (j != i && c >= min_cos && c <= max_cos) near.emplace_back(-c, j);
    }
    std::sort(near.begin(), near.end());
    for (int n = 0; n < std::min<int>(options.partners, static_cast<int>(near.size())); ++n)
      pairs.emplace(std::min(i, near[size_t(n)].second), std::max(i, near[size_t(n)].second));
  }

  cv::BFMatcher matcher(cv::NORM_L2);
  TriangulationOptions triangulation;
  triangulation.refine = false;
  triangulation.min_angle_deg = 1.0;
  FacePointStats out;
  out.views = static_cast<int>(views.size());
  points->clear();
  for (const auto& [i, j] : pairs) {
    const FaceView& a = views[size_t(i)];
    const FaceView& b = views[size_t(j)];
    if (a.descriptors.rows < 2 || b.descriptors.rows < 2) continue;
    ++out.pairs;
    std::vector<std::vector<cv::DMatch>> matches;
    matcher.knnMatch(a.descriptors, b.descriptors, matches, 2);
    for (const std::vector<cv::DMatch>& m : matches) {
      if (m.size() < 2 || !(m[0].distance < options.ratio * m[1].distance)) continue;
      const TriangulationResult r = TriangulatePoint(
          {{a.projection, a.pixels[size_t(m[0].queryIdx)]}, {b.projection, b.pixels[size_t(m[0].trainIdx)]}},
          triangulation);
      if (!r.ok || r.quality != TriangulationQuality::kGood || r.rms_px > options.max_reprojection_px) continue;
      points->push_back(r.point);
    }
  }
  out.points = static_cast<int>(points->size());
  HF_LOG(Debug) << "face points: " << out.points << " points from " << out.pairs << " pairs of " << out.views
               << " views";
  *stats = out;
  return Status::Ok();
}

}  // namespace headforge
