#include "calibration/head_pose.h"

#include <algorithm>
#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <array>
#include <cmath>

#include "calibration/pnp.h"
#include "calibration/reprojection_cost.h"
#include "core/log.h"

namespace headforge {

Status HeadPoseOptions::Check() const {
  if (focal < 0) return Status::InvalidArgument("head-pose focal must be >= 0 (0 estimates it)");
  if (!(fov_deg >= 0 && fov_deg < 180))
    return Status::InvalidArgument("--fov must be a horizontal field of view in degrees, between 0 and 180");
  if (focal > 0 && fov_deg > 0) return Status::InvalidArgument("give --focal or --fov, not both");
  if (!(prior_fov_deg > 0 && prior_fov_deg < 180) || !(prior_sigma >= 0))
    return Status::InvalidArgument("head-pose focal prior: the field of view must be in (0, 180) and sigma >= 0");
  if (!(robust_px > 0)) return Status::InvalidArgument("head-pose robust scale must be positive");
  if (jaw_weight < 0 || smoothness < 0) return Status::InvalidArgument("head-pose weights must be >= 0");
  if (refine != "face-model" && refine != "off")
    return Status::InvalidArgument("head-pose refine must be face-model or off");
  if (refine_rounds < 1) return Status::InvalidArgument("head-pose refine rounds must be at least 1");
  if (!(refine_mesh_weight >= 0)) return Status::InvalidArgument("--head-pose-mesh-weight must be zero or positive");
  return Status::Ok();
}

double FocalFromFov(double fov_deg, int source_width, double crop_scale) {
  constexpr double kPi = 3.14159265358979323846;
  return 0.5 * source_width / std::tan(0.5 * fov_deg * kPi / 180.0) * crop_scale;
}

namespace {

// Landmarks that move with the skull alone: nose bridge and base, eye corners.
constexpr int kRigidLandmarks[] = {27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 39, 42, 45};

struct FramePose {
  double rotation[3] = {0, 0, 0};
  double translation[3] = {0, 0, 0.5};
};

Eigen::Isometry3d ToIsometry(const FramePose& p) {
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(p.rotation, ceres::ColumnMajorAdapter3x3(r.data()));
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = r;
  t.translation() = Eigen::Vector3d(p.translation[0], p.translation[1], p.translation[2]);
  return t;
}

FramePose FromIsometry(const Eigen::Isometry3d& t) {
  FramePose p;
  const Eigen::Matrix3d r = t.linear();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r.data()), p.rotation);
  for (int i = 0; i < 3; ++i) p.translation[i] = t.translation()[i];
  return p;
}

double Weight(int landmark, const HeadPoseOptions& o) { return landmark <= 16 ? o.jaw_weight : 1.0; }

// Total robust PnP error of a focal guess over a subset of frames.
double FocalScore(double focal, const std::vector<Eigen::Vector3d>& object,
                  const std::vector<std::optional<Landmarks68>>& landmarks, const std::vector<int>& frames,
                  const Eigen::Vector2d& principal) {
  Eigen::Matrix3d k;
  k << focal, 0, principal.x(), 0, focal, principal.y(), 0, 0, 1;
  // Rigid landmarks only: the mouth and brows move with expressions, the jaw
  // contour slides along the silhouette; either would bias the focal length.
  double total = 0;
  for (int f : frames) {
    std::vector<Eigen::Vector3d> obj;
    std::vector<Eigen::Vector2d> px;
    for (int i : kRigidLandmarks) {
      obj.push_back(object[i]);
      px.emplace_back((*landmarks[f])[i].x, (*landmarks[f])[i].y);
    }
    const PnpResult r = SolvePnp(obj, px, k);
    total += r.ok ? r.rms_px : 1e3;
  }
  return total;
}

}  // namespace

Status EstimateHeadPoseCameras(const FaceModel& model, const std::vector<std::optional<Landmarks68>>& landmarks,
                               int width, int height, const Eigen::Vector2d& principal,
                               const HeadPoseOptions& options, HeadPoseResult* result) {
  HF_RETURN_IF_ERROR(options.Check());
  if (model.landmarks_ibug68().size() != 68)
    return Status::InvalidArgument("the face model has no iBUG-68 landmark vertices");
  std::vector<Eigen::Vector3d> object;
  if (options.landmark_points.size() == 68) {
    object = options.landmark_points;
  } else {
    for (int v : model.landmarks_ibug68()) object.push_back(model.neutral().col(v).cast<double>());
  }
  std::vector<int> observed;
  for (size_t f = 0; f < landmarks.size(); ++f)
    if (landmarks[f]) observed.push_back(static_cast<int>(f));
  if (observed.empty())
    return Status::DataError("no frame has landmarks: head-pose cameras need the face in at least one frame");

  // Focal length: the best of a log-spaced sweep on up to 25 frames, refined
  // by golden-section search, then jointly with the poses below.
  double focal = options.focal;
  if (focal <= 0) {
    std::vector<int> subset;
    const size_t step = std::max<size_t>(1, observed.size() / 25);
    for (size_t i = 0; i < observed.size(); i += step) subset.push_back(observed[i]);
    const double size = std::max(width, height);
    double best = 0, best_score = 1e300;
    for (double m = 0.4; m <= 8.0; m *= 1.15) {
      const double score = FocalScore(m * size, object, landmarks, subset, principal);
      if (score < best_score) {
        best_score = score;
        best = m * size;
      }
    }
    double lo = best / 1.15, hi = best * 1.15;
    for (int it = 0; it < 20; ++it) {
      const double a = lo + 0.382 * (hi - lo), b = lo + 0.618 * (hi - lo);
      if (FocalScore(a, object, landmarks, subset, principal) < FocalScore(b, object, landmarks, subset, principal))
        hi = b;
      else
        lo = a;
    }
    focal = 0.5 * (lo + hi);
  }

  // Per-frame PnP starts.
  Eigen::Matrix3d k;
  k << focal, 0, principal.x(), 0, focal, principal.y(), 0, 0, 1;
  std::vector<FramePose> poses(landmarks.size());
  for (int f : observed) {
    std::vector<Eigen::Vector2d> px;
    for (int i = 0; i < 68; ++i) px.emplace_back((*landmarks[f])[i].x, (*landmarks[f])[i].y);
    const PnpResult r = SolvePnp(object, px, k);
    if (r.ok) poses[f] = FromIsometry(r.cam_from_object);
  }

  // Joint refinement with a robust loss; the jaw contour counts less (detectors
  // follow the silhouette, the model has fixed vertices).
  ceres::Problem problem;
  double focal_param = focal;
  for (int f : observed)
    for (int i = 0; i < 68; ++i) {
      const Eigen::Vector2d px((*landmarks[f])[i].x, (*landmarks[f])[i].y);
      problem.AddResidualBlock(PosedReprojectionCost::Create(object[i], px, principal, Weight(i, options)),
                               new ceres::HuberLoss(options.robust_px), &focal_param, poses[f].rotation,
                               poses[f].translation);
    }
  const bool free_focal = options.focal <= 0 && observed.size() >= 2;
  if (!free_focal) problem.SetParameterBlockConstant(&focal_param);
  if (free_focal && options.prior_focal > 0 && options.prior_sigma > 0)
    problem.AddResidualBlock(LogPriorCost::Create(options.prior_focal, options.robust_px / options.prior_sigma), nullptr,
                             &focal_param);
  if (options.smoothness > 0)
    for (size_t a = 0; a + 1 < observed.size(); ++a) {
      const int f0 = observed[a], f1 = observed[a + 1];
      const double gap = f1 - f0;
      problem.AddResidualBlock(PoseSmoothnessCost::Create(options.smoothness * 20.0 / gap, options.smoothness * 200.0 / gap),
                               nullptr, poses[f0].rotation, poses[f0].translation, poses[f1].rotation,
                               poses[f1].translation);
    }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::SPARSE_SCHUR;
  solver.max_num_iterations = options.max_iterations;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  if (!summary.IsSolutionUsable() || !std::isfinite(focal_param) || focal_param <= 0)
    return Status::DataError("head-pose refinement failed: " + summary.message);

  HeadPoseResult out;
  out.focal = focal_param;
  if (free_focal) out.focal_log_sigma = LogStandardDeviation(&problem, &focal_param, summary.final_cost);
  out.cam_from_head.resize(landmarks.size());
  out.observed.assign(landmarks.size(), false);
  out.rms_px.assign(landmarks.size(), 0.0);
  std::vector<double> errors;
  for (int f : observed) {
    out.observed[f] = true;
    out.cam_from_head[f] = ToIsometry(poses[f]);
    double sum = 0;
    for (int i = 17; i < 68; ++i) {
      const Eigen::Vector3d p = out.cam_from_head[f] * object[i];
      const Eigen::Vector2d proj(focal_param * p.x() / p.z() + principal.x(), focal_param * p.y() / p.z() + principal.y());
      const double e = (proj - Eigen::Vector2d((*landmarks[f])[i].x, (*landmarks[f])[i].y)).norm();
      sum += e * e;
      errors.push_back(e);
    }
    out.rms_px[f] = std::sqrt(sum / 51.0);
  }
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  out.median_px = errors[errors.size() / 2];
  // Frames without landmarks: interpolate between the nearest observed ones.
  for (size_t f = 0; f < landmarks.size(); ++f) {
    if (out.observed[f]) continue;
    const auto next = std::lower_bound(observed.begin(), observed.end(), static_cast<int>(f));
    if (next == observed.begin()) {
      out.cam_from_head[f] = out.cam_from_head[observed.front()];
    } else if (next == observed.end()) {
      out.cam_from_head[f] = out.cam_from_head[observed.back()];
    } else {
      const int b = *next, a = *(next - 1);
      const double s = (static_cast<double>(f) - a) / (b - a);
      const Eigen::Quaterniond qa(out.cam_from_head[a].linear()), qb(out.cam_from_head[b].linear());
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.linear() = qa.slerp(s, qb).toRotationMatrix();
      t.translation() = (1 - s) * out.cam_from_head[a].translation() + s * out.cam_from_head[b].translation();
      out.cam_from_head[f] = t;
    }
  }
  *result = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
