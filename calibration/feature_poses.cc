#include "calibration/feature_poses.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>
#include <sstream>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/triangulation.h"
#include "capture/landmarks.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/rotation.h"
#include "core/statistics.h"

namespace headforge {
namespace {

constexpr double kDegrees = 180.0 / M_PI;

// The head's rigid part in a frame: the hull of the forehead, the brows, the
// nose and the jaw line's upper ends, without the eyes (their lids move) and kept off the
// silhouette.
cv::Mat RigidFaceMask(const Landmarks68& lm, cv::Size size) {
  std::vector<cv::Point> hull_points;
  for (int i : {0, 1, 15, 16}) hull_points.push_back(lm[size_t(i)]);
  for (int i = 17; i <= 35; ++i) hull_points.push_back(lm[size_t(i)]);
  // The forehead up to the hairline: the brows raised by the nose's length and a fifth.
  const cv::Point2f up = 1.2f * (lm[27] - lm[33]);
  for (int i = 17; i <= 26; ++i) hull_points.push_back(lm[size_t(i)] + up);
  std::vector<cv::Point> hull;
  cv::convexHull(hull_points, hull);
  cv::Mat mask = cv::Mat::zeros(size, CV_8U);
  cv::fillConvexPoly(mask, hull, cv::Scalar(255));
  const double eyes = cv::norm(lm[ibug::kRightEyeOuter] - lm[ibug::kLeftEyeOuter]);
  const int edge = std::max(2, static_cast<int>(std::lround(0.05 * eyes)));
  cv::erode(mask, mask, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * edge + 1, 2 * edge + 1)));
  for (int first : {36, 42}) {
    std::vector<cv::Point> eye;
    for (int i = first; i < first + 6; ++i) eye.push_back(lm[size_t(i)]);
    cv::Mat eye_mask = cv::Mat::zeros(size, CV_8U);
    cv::fillConvexPoly(eye_mask, eye, cv::Scalar(255));
    const int grow = std::max(2, static_cast<int>(std::lround(0.4 * cv::norm(eye[0] - eye[3]))));
    cv::dilate(eye_mask, eye_mask, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * grow + 1, 2 * grow + 1)));
    mask.setTo(0, eye_mask);
  }
  return mask;
}

struct FrameFeatures {
  int view = 0;  // index into the camera set's views
  std::vector<Eigen::Vector2d> pixels;
  std::vector<cv::Point2f> points;
  cv::Mat descriptors;
};

struct Sighting {
  int frame = 0;  // index into the frames
  int feature = 0;
};

int Root(std::vector<int>* parent, int x) {
  while ((*parent)[size_t(x)] != x) {
    (*parent)[size_t(x)] = (*parent)[size_t((*parent)[size_t(x)])];
    x = (*parent)[size_t(x)];
  }
  return x;
}

// A head-frame point seen in a frame whose pose is a small rotation `delta`
// (angle-axis) after the starting rotation R0, and a translation:
// x_cam = R(delta) R0 X + t. Parameters: pose[6] = delta, t; point[3].
struct HeadFeatureCost {
  HeadFeatureCost(const Eigen::Matrix3d& r0, const Eigen::Matrix3d& k, const Eigen::Vector2d& pixel)
      : r0_(r0), k_(k), pixel_(pixel) {}

  template <typename T>
  bool operator()(const T* pose, const T* point, T* residual) const {
    T x[3];
    for (int r = 0; r < 3; ++r) x[r] = T(r0_(r, 0)) * point[0] + T(r0_(r, 1)) * point[1] + T(r0_(r, 2)) * point[2];
    T c[3];
    ceres::AngleAxisRotatePoint(pose, x, c);
    for (int r = 0; r < 3; ++r) c[r] += pose[3 + r];
    residual[0] = T(k_(0, 0)) * c[0] / c[2] + T(k_(0, 2)) - T(pixel_.x());
    residual[1] = T(k_(1, 1)) * c[1] / c[2] + T(k_(1, 2)) - T(pixel_.y());
    return true;
  }

  Eigen::Matrix3d r0_, k_;
  Eigen::Vector2d pixel_;
};

// The pull toward the starting pose: delta / sigma_r, (t - t0) / sigma_t.
struct PosePriorCost {
  PosePriorCost(const Eigen::Vector3d& t0, double sigma_rad, double sigma_m) : t0_(t0), sr_(sigma_rad), st_(sigma_m) {}
  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    for (int i = 0; i < 3; ++i) residual[i] = pose[i] / T(sr_);
    for (int i = 0; i < 3; ++i) residual[3 + i] = (pose[3 + i] - T(t0_[i])) / T(st_);
    return true;
  }
  Eigen::Vector3d t0_;
  double sr_, st_;
};

// The features of every frame with landmarks, in the rigid face mask.
Status DetectFrames(const IngestedCapture& capture, const std::string& camera, const CameraSet& cameras,
                    const FeaturePoseOptions& options, std::vector<FrameFeatures>* frames) {
  const CameraIntrinsics* intrinsics = cameras.FindCamera(camera);
  std::vector<std::pair<int, const IngestedFrame*>> views;  // a view's index, its frame
  for (int v = 0; v < static_cast<int>(cameras.views.size()); ++v) {
    const CameraView& view = cameras.views[size_t(v)];
    if (view.camera != camera || !view.registered) continue;
    const IngestedFrame* frame = capture.FindFrame(camera, view.frame);
    if (frame != nullptr && frame->landmarks) views.emplace_back(v, frame);
  }
  std::sort(views.begin(), views.end(), [&](const auto& a, const auto& b) {
    return cameras.views[size_t(a.first)].frame < cameras.views[size_t(b.first)].frame;
  });
  frames->assign(views.size(), FrameFeatures());
  std::vector<Status> errors(views.size());
  ParallelFor(static_cast<int>(views.size()), options.threads, [&](int i, int) {
    const CameraView& view = cameras.views[size_t(views[size_t(i)].first)];
    const fs::path path = capture.FramePath(camera, view.frame);
    const cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (image.empty()) {
      errors[size_t(i)] = Status::IoError("head-pose features: cannot read the frame " + path.string() +
                                          ": the workspace's frames are missing or damaged; run headforge ingest "
                                          "again (or calibrate with --head-pose-features=false)");
      return;
    }
    FrameFeatures& f = (*frames)[size_t(i)];
    f.view = views[size_t(i)].first;
    std::vector<cv::KeyPoint> keypoints;
    cv::Ptr<cv::SIFT> sift = cv::SIFT::create(0, 3, options.contrast_threshold);
    sift->detectAndCompute(image, RigidFaceMask(*views[size_t(i)].second->landmarks, image.size()), keypoints,
                           f.descriptors);
    for (const cv::KeyPoint& p : keypoints) {
      f.points.push_back(p.pt);
      f.pixels.push_back(intrinsics->Undistort(Eigen::Vector2d(p.pt.x, p.pt.y)));
    }
  });
  for (const Status& s : errors) HF_RETURN_IF_ERROR(s);
  return Status::Ok();
}

// Matches between frames at offsets 1, 2, 4, ..., each pair's kept by a
// fundamental matrix, chained into tracks of distinct frames.
std::vector<std::vector<Sighting>> BuildTracks(const std::vector<FrameFeatures>& frames,
                                               const FeaturePoseOptions& options) {
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < static_cast<int>(frames.size()); ++i)
    for (int off = 1; off <= options.max_offset && i + off < static_cast<int>(frames.size()); off *= 2)
      pairs.emplace_back(i, i + off);
  std::vector<std::vector<std::pair<int, int>>> matched(pairs.size());
  ParallelFor(static_cast<int>(pairs.size()), options.threads, [&](int p, int) {
    const FrameFeatures& a = frames[size_t(pairs[size_t(p)].first)];
    const FrameFeatures& b = frames[size_t(pairs[size_t(p)].second)];
    if (a.descriptors.rows < 2 || b.descriptors.rows < 2) return;
    cv::BFMatcher matcher(cv::NORM_L2);
    std::vector<std::vector<cv::DMatch>> knn;
    matcher.knnMatch(a.descriptors, b.descriptors, knn, 2);
    std::vector<std::pair<int, int>> candidates;
    std::vector<cv::Point2f> pa, pb;
    for (const auto& m : knn) {
      if (m.size() < 2 || !(m[0].distance < options.ratio * m[1].distance)) continue;
      candidates.emplace_back(m[0].queryIdx, m[0].trainIdx);
      pa.push_back(a.points[size_t(m[0].queryIdx)]);
      pb.push_back(b.points[size_t(m[0].trainIdx)]);
    }
    if (candidates.size() < 12) return;
    std::vector<uchar> inlier;
    const cv::Mat f = cv::findFundamentalMat(pa, pb, cv::FM_RANSAC, options.ransac_px, 0.999, inlier);
    if (f.empty()) return;
    for (size_t k = 0; k < candidates.size(); ++k)
      if (inlier[k]) matched[size_t(p)].push_back(candidates[k]);
  });
  std::vector<int> base(frames.size() + 1, 0);
  for (size_t i = 0; i < frames.size(); ++i) base[i + 1] = base[i] + static_cast<int>(frames[i].pixels.size());
  std::vector<int> parent(size_t(base.back()));
  std::iota(parent.begin(), parent.end(), 0);
  for (size_t p = 0; p < pairs.size(); ++p)
    for (const auto& [ka, kb] : matched[p]) {
      const int ra = Root(&parent, base[size_t(pairs[p].first)] + ka);
      const int rb = Root(&parent, base[size_t(pairs[p].second)] + kb);
      if (ra != rb) parent[size_t(ra)] = rb;
    }
  std::map<int, std::vector<Sighting>> groups;
  for (int i = 0; i < static_cast<int>(frames.size()); ++i)
    for (int k = 0; k < static_cast<int>(frames[size_t(i)].pixels.size()); ++k) {
      const int node = base[size_t(i)] + k;
      groups[Root(&parent, node)].push_back({i, k});
    }
  std::vector<std::vector<Sighting>> tracks;
  int conflicting = 0;
  for (auto& [root, sightings] : groups) {
    if (static_cast<int>(sightings.size()) < options.min_track) continue;
    bool distinct = true;
    for (size_t s = 1; s < sightings.size(); ++s) distinct = distinct && sightings[s].frame != sightings[s - 1].frame;
    if (distinct) tracks.push_back(std::move(sightings));
    else ++conflicting;
  }
  std::vector<double> per_frame, per_pair;
  for (const FrameFeatures& f : frames) per_frame.push_back(double(f.pixels.size()));
  for (const auto& m : matched) per_pair.push_back(double(m.size()));
  HF_LOG(Debug) << "feature poses: features a frame " << Median(per_frame) << ", matches a pair " << Median(per_pair)
                << ", tracks " << tracks.size() << ", " << conflicting << " dropped as conflicting";
  return tracks;
}

}  // namespace

Status FeaturePoseOptions::Check() const {
  if (!(contrast_threshold > 0) || !(ratio > 0 && ratio <= 1) || !(ransac_px > 0) || max_offset < 1 || min_track < 2 ||
      !(robust_px > 0) || !(prior_rotation_deg > 0) || !(prior_translation_mm > 0) || max_iterations < 1 ||
      min_tracks < 1 || !(max_median_px > 0))
    return Status::InvalidArgument("feature poses: an option is out of range");
  return Status::Ok();
}

std::string FeaturePoseStats::Summary() const {
  std::ostringstream s;
  s.precision(3);
  if (!left.empty()) {
    s << left << "; the poses stay as they were (" << frames << " frames searched, " << seconds << " s)";
    return s.str();
  }
  s << tracks << " points on the rigid face in " << frames_moved << " of " << frames << " frames (" << observations
    << " sightings), reprojection " << median_px_before << " -> " << median_px_after << " px, poses moved "
    << median_change_deg << " deg / " << median_change_mm << " mm (median), " << seconds << " s";
  return s.str();
}

namespace {

// The bundle adjustment's state: each frame's pose as a rotation after its
// starting one and a translation, the tracks' points, which sightings count.
struct Adjustment {
  std::vector<std::array<double, 6>> poses;
  std::vector<Eigen::Matrix3d> r0;
  std::vector<Eigen::Vector3d> t0;
  std::vector<Eigen::Vector3d> points;
  std::vector<const std::vector<Sighting>*> tracks;
  std::vector<std::vector<bool>> use;
  std::vector<int> seen;  // sightings per frame
  Eigen::Matrix3d k;

  HeadFeatureCost Cost(const std::vector<FrameFeatures>& frames, const Sighting& s) const {
    const size_t f = size_t(s.frame);
    return HeadFeatureCost(r0[f], k, frames[f].pixels[size_t(s.feature)]);
  }
  double ResidualPx(const std::vector<FrameFeatures>& frames, size_t p, const Sighting& s) const {
    double residual[2];
    Cost(frames, s)(poses[size_t(s.frame)].data(), points[p].data(), residual);
    return std::hypot(residual[0], residual[1]);
  }
};

// The starting poses, and the tracks triangulated with them (those that
// reproject within 4 px and lie within 30 cm of the head's origin).
void StartAdjustment(const std::vector<FrameFeatures>& frames, const std::vector<std::vector<Sighting>>& tracks,
                     const CameraSet& cameras, const Eigen::Matrix3d& k, Adjustment* a, double* median_px) {
  a->k = k;
  std::vector<Eigen::Matrix<double, 3, 4>> projection(frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    const Eigen::Isometry3d& pose = cameras.views[size_t(frames[i].view)].cam_from_world;
    a->r0.push_back(pose.rotation());
    a->t0.push_back(pose.translation());
    a->poses.push_back({0, 0, 0, pose.translation().x(), pose.translation().y(), pose.translation().z()});
    projection[i] = k * pose.matrix().topRows<3>();
  }
  TriangulationOptions triangulation;
  triangulation.min_angle_deg = 0.5;
  std::vector<double> rms;
  for (const std::vector<Sighting>& track : tracks) {
    std::vector<TriangulationView> views;
    for (const Sighting& s : track)
      views.push_back({projection[size_t(s.frame)], frames[size_t(s.frame)].pixels[size_t(s.feature)], 1.0});
    const TriangulationResult r = TriangulatePoint(views, triangulation);
    if (!r.ok || r.quality == TriangulationQuality::kFailed || r.rms_px > 4.0 || r.point.norm() > 0.3) continue;
    a->points.push_back(r.point);
    a->tracks.push_back(&track);
    a->use.emplace_back(track.size(), true);
    rms.push_back(r.rms_px);
  }
  a->seen.assign(frames.size(), 0);
  for (const auto* track : a->tracks)
    for (const Sighting& s : *track) ++a->seen[size_t(s.frame)];
  *median_px = Median(rms);
}

// Two solves, the sightings over 3 robust scales off the first dropped.
void Adjust(const std::vector<FrameFeatures>& frames, const FeaturePoseOptions& options, Adjustment* a,
            ceres::Solver::Summary* summary) {
  const double sigma_r = options.prior_rotation_deg / kDegrees, sigma_t = options.prior_translation_mm / 1000.0;
  for (int pass = 0; pass < 2 && !a->points.empty(); ++pass) {
    ceres::Problem problem;
    for (size_t p = 0; p < a->tracks.size(); ++p)
      for (size_t s = 0; s < a->tracks[p]->size(); ++s) {
        if (!a->use[p][s]) continue;
        const Sighting& sighting = (*a->tracks[p])[s];
        problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<HeadFeatureCost, 2, 6, 3>(new HeadFeatureCost(a->Cost(frames, sighting))),
            new ceres::HuberLoss(options.robust_px), a->poses[size_t(sighting.frame)].data(), a->points[p].data());
      }
    for (size_t f = 0; f < frames.size(); ++f) {
      if (!problem.HasParameterBlock(a->poses[f].data())) continue;
      if (a->seen[f] < options.min_frame_observations) {
        problem.SetParameterBlockConstant(a->poses[f].data());
        continue;
      }
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<PosePriorCost, 6, 6>(new PosePriorCost(a->t0[f], sigma_r, sigma_t)),
          nullptr, a->poses[f].data());
    }
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::SPARSE_SCHUR;
    solver.max_num_iterations = options.max_iterations;
    // One thread: the Schur complement's sums in a fixed order, so that a
    // resumed run writes the same cameras as an uninterrupted one.
    solver.num_threads = 1;
    ceres::Solve(solver, &problem, summary);
    for (size_t p = 0; p < a->tracks.size(); ++p)
      for (size_t s = 0; s < a->tracks[p]->size(); ++s)
        a->use[p][s] = a->ResidualPx(frames, p, (*a->tracks[p])[s]) < 3.0 * options.robust_px;
  }
}

}  // namespace

Status RefineHeadPosesWithFeatures(const IngestedCapture& capture, const std::string& camera,
                                   const FeaturePoseOptions& options, CameraSet* cameras, FeaturePoseStats* stats) {
  HF_RETURN_IF_ERROR(options.Check());
  const auto start = std::chrono::steady_clock::now();
  const CameraIntrinsics* intrinsics = cameras->FindCamera(camera);
  if (intrinsics == nullptr) return Status::NotFound("feature poses: no intrinsics for camera " + camera);
  std::vector<FrameFeatures> frames;
  HF_RETURN_IF_ERROR(DetectFrames(capture, camera, *cameras, options, &frames));
  FeaturePoseStats out;
  out.frames = static_cast<int>(frames.size());
  const std::vector<std::vector<Sighting>> tracks = BuildTracks(frames, options);
  Adjustment a;
  StartAdjustment(frames, tracks, *cameras, intrinsics->K(), &a, &out.median_px_before);
  out.tracks = static_cast<int>(a.points.size());
  ceres::Solver::Summary summary;
  Adjust(frames, options, &a, &summary);

  std::vector<double> after, change_deg, change_mm;
  for (size_t p = 0; p < a.tracks.size(); ++p)
    for (size_t s = 0; s < a.tracks[p]->size(); ++s)
      if (a.use[p][s]) after.push_back(a.ResidualPx(frames, p, (*a.tracks[p])[s]));
  out.observations = static_cast<int>(after.size());
  out.median_px_after = Median(after);
  // Too little texture to follow, or an adjustment that does not fit its own
  // sightings: the poses stay as they were.
  if (out.tracks < options.min_tracks) {
    out.left = "too few features to follow (" + std::to_string(out.tracks) + " points, need " +
               std::to_string(options.min_tracks) + ")";
  } else if (!(out.median_px_after <= options.max_median_px)) {
    std::ostringstream why;
    why << "the adjusted features reproject " << out.median_px_after << " px off (limit " << options.max_median_px
        << " px)";
    out.left = why.str();
  }
  // The adjusted poses, then the one rigid move of the head frame that takes
  // them back onto the starting ones on average: the features decide the
  // motion between frames, the landmarks where the head frame sits.
  std::vector<size_t> moved;
  std::vector<Eigen::Isometry3d> adjusted;
  Eigen::Matrix3d rotation_sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d translation_sum = Eigen::Vector3d::Zero();
  for (size_t f = 0; f < frames.size() && out.left.empty(); ++f) {
    if (a.seen[f] < options.min_frame_observations) continue;
    const Eigen::Vector3d delta(a.poses[f][0], a.poses[f][1], a.poses[f][2]);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = a.r0[f];
    if (delta.norm() > 0) pose.linear() = Eigen::AngleAxisd(delta.norm(), delta.normalized()).toRotationMatrix() * a.r0[f];
    pose.translation() = Eigen::Vector3d(a.poses[f][3], a.poses[f][4], a.poses[f][5]);
    const Eigen::Isometry3d& start = cameras->views[size_t(frames[f].view)].cam_from_world;
    const Eigen::Isometry3d back = pose.inverse() * start;  // new * back = start
    rotation_sum += back.rotation();
    translation_sum += back.translation();
    moved.push_back(f);
    adjusted.push_back(pose);
  }
  if (!moved.empty()) {
    Eigen::Isometry3d anchor = Eigen::Isometry3d::Identity();
    anchor.linear() = NearestRotation(rotation_sum);  // the chordal mean
    anchor.translation() = translation_sum / double(moved.size());
    for (size_t i = 0; i < moved.size(); ++i) {
      Eigen::Isometry3d& pose = cameras->views[size_t(frames[moved[i]].view)].cam_from_world;
      const Eigen::Isometry3d anchored = adjusted[i] * anchor;
      change_deg.push_back(Eigen::AngleAxisd(anchored.rotation() * pose.rotation().transpose()).angle() * kDegrees);
      change_mm.push_back((anchored.translation() - pose.translation()).norm() * 1000.0);
      pose = anchored;
      ++out.frames_moved;
    }
  }
  out.median_change_deg = Median(change_deg);
  out.median_change_mm = Median(change_mm);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  HF_LOG(Debug) << "feature poses: " << summary.BriefReport();
  *stats = out;
  return Status::Ok();
}

}  // namespace headforge
