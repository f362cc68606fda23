#include "calibration/align.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <Eigen/SVD>
#include <ceres/rotation.h>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calibration/face_points.h"
#include "calibration/landmark_embedding.h"
#include "calibration/pnp.h"
#include "calibration/reprojection_cost.h"
#include "calibration/surface_fit.h"
#include "calibration/triangulation.h"
#include "core/log.h"
#include "core/rotation.h"

namespace headforge {

Status FindMisplacedViews(const IngestedCapture& capture, const CameraSet& head_cameras,
                          std::vector<MisplacedView>* misplaced) {
  misplaced->clear();
  for (const IngestedCamera& cam : capture.cameras) {
    const CameraIntrinsics* lens = head_cameras.FindCamera(cam.name);
    if (!lens) continue;
    for (const IngestedFrame& f : cam.frames) {
      const CameraView* view = head_cameras.FindView(cam.name, f.index);
      if (!view || !view->registered) continue;
      // The head frame's origin (the face model's, inside the head) in the camera.
      const Eigen::Vector3d centre = view->cam_from_world.translation();
      const double w = lens->width, h = lens->height;
      const bool behind = centre.z() <= 0;
      const double u = behind ? 0 : lens->fx * centre.x() / centre.z() + lens->cx;
      const double v = behind ? 0 : (lens->fy > 0 ? lens->fy : lens->fx) * centre.y() / centre.z() + lens->cy;
      if (!behind && u > -0.25 * w && u < 1.25 * w && v > -0.25 * h && v < 1.25 * h) continue;
      const fs::path mask_path = capture.MaskPath(cam.name, f.index);
      if (capture.workspace.empty() || !fs::exists(mask_path)) continue;
      const cv::Mat mask = cv::imread(mask_path.string(), cv::IMREAD_GRAYSCALE);
      if (mask.empty()) return Status::DataError("cannot read the mask " + mask_path.string());
      if (cv::countNonZero(mask > 127) < 0.01 * mask.total()) continue;
      misplaced->push_back({cam.name, f.index, behind});
    }
  }
  return Status::Ok();
}

namespace {

// Leaves out of result->cameras the views FindMisplacedViews finds, and says
// so in result->message; fails when they are more than half.
Status DropMisplacedViews(const IngestedCapture& capture, AlignResult* result) {
  HF_RETURN_IF_ERROR(FindMisplacedViews(capture, result->cameras, &result->misplaced));
  if (result->misplaced.empty()) return Status::Ok();
  std::map<std::string, int> per_camera;
  int behind = 0;
  for (const MisplacedView& m : result->misplaced) {
    ++per_camera[m.camera];
    behind += m.behind;
  }
  std::string which;
  for (const auto& [camera, count] : per_camera)
    which += (which.empty() ? "" : ", ") + camera + " (" + std::to_string(count) + ")";
  const int registered = result->cameras.registered();
  const std::string what = std::to_string(result->misplaced.size()) + " of " + std::to_string(registered) +
                           " registered views show the head in their frames, but their cameras were placed with it " +
                           (behind == int(result->misplaced.size()) ? "behind them" : "behind them or outside their frame") +
                           ": " + which;
  if (2 * result->misplaced.size() > size_t(registered))
    return Status::DataError(what + ". The calibration is probably wrong; try calibrate with a rig file (--mode rig), "
                             "--rig-instants 3, --matcher exhaustive or --max-features 8192");
  for (const MisplacedView& m : result->misplaced)
    for (CameraView& v : result->cameras.views)
      if (v.camera == m.camera && v.frame == m.frame) v.registered = false;
  HF_LOG(Warning) << "align: " << what << "; they are left out (a rig file, --mode rig, gives a dome's cameras "
                  << "where they are; --drop-misplaced=false keeps them)";
  result->message += (result->message.empty() ? "" : ", ") + std::to_string(result->misplaced.size()) +
                     " misplaced views left out: " + which;
  return Status::Ok();
}

}  // namespace

CameraSet ToHeadFrame(const CameraSet& cameras, const Sim3& head_from_world) {
  // x_world = world_from_head(x_head) = R^T (x_head - t) / s. Scaling camera
  // coordinates by s leaves projections unchanged and keeps the frame metric:
  // cam_from_head = [R_c R^T | s t_c - R_c R^T t].
  CameraSet out = cameras;
  out.frame = "head";
  const Eigen::Matrix3d rt = head_from_world.rotation.transpose();
  for (auto& v : out.views) {
    if (!v.registered) continue;
    const Eigen::Matrix3d rc = v.cam_from_world.linear();
    const Eigen::Vector3d tc = v.cam_from_world.translation();
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = rc * rt;
    t.translation() = head_from_world.scale * tc - rc * rt * head_from_world.translation;
    v.cam_from_world = t;
  }
  return out;
}

namespace {

struct Observation {
  Eigen::Matrix<double, 3, 4> projection;
  Eigen::Vector2d pixel;
};

struct ViewPose {
  Eigen::Isometry3d cam_from_world;  // from calibrate
  Eigen::Isometry3d cam_from_head;   // from PnP of the view's landmarks against the model (world frame only)
  bool frontal_by_pnp = false;       // PnP's own yaw is within the limit (world frame only)
  double weight = 1.0;               // in the mean of the views' rotations
  std::vector<Observation> landmarks;  // its 68 landmarks (undistorted) with its projection
  std::string camera;                 // for the log
};

// The views' landmarks grouped by landmark, as triangulation wants them.
std::vector<std::vector<Observation>> ByLandmark(const std::vector<ViewPose>& views) {
  std::vector<std::vector<Observation>> out(68);
  for (const ViewPose& v : views)
    for (size_t i = 0; i < v.landmarks.size() && i < 68; ++i) out[i].push_back(v.landmarks[i]);
  return out;
}

// The views that see the face within about `max_yaw_deg` of frontal and
// `max_elevation_deg` of level, judged by geometry: their camera centres as
// seen from `face_centre` (world) in a head frame rotated by `head_from_world`.
// Detectors shrink a turned head's pose toward frontal, so a view chosen by
// its own PnP yaw may be far more turned than it says, and a set chosen that
// way is lopsided wherever the detector gives way on one side. Each view is
// weighted 1 up to 5 degrees inside a limit, falling to 0 at 5 degrees
// outside it, so that the choice moves smoothly with the rotation (a hard
// edge can settle with one side's last view out and the other's in).
std::vector<ViewPose> ViewsFacing(const std::vector<ViewPose>& views, const Eigen::Matrix3d& head_from_world,
                                  const Eigen::Vector3d& face_centre, double max_yaw_deg, double max_elevation_deg) {
  constexpr double kTaperDeg = 5.0;
  auto ramp = [](double angle, double limit) { return std::clamp((limit + kTaperDeg - angle) / (2 * kTaperDeg), 0.0, 1.0); };
  std::vector<ViewPose> out;
  for (const ViewPose& v : views) {
    const Eigen::Vector3d d = head_from_world * (v.cam_from_world.inverse().translation() - face_centre);
    const double yaw = std::atan2(d.x(), d.z()) * 180.0 / 3.14159265358979323846;
    const double elevation = std::atan2(d.y(), std::hypot(d.x(), d.z())) * 180.0 / 3.14159265358979323846;
    const double weight = ramp(std::abs(yaw), max_yaw_deg) * ramp(std::abs(elevation), max_elevation_deg);
    if (weight <= 0) continue;
    out.push_back(v);
    out.back().weight = weight;
  }
  return out;
}

// head_from_world from the views' own head poses: each view gives a rotation
// head_from_world = head_from_cam * cam_from_world, and their robust chordal
// mean is the rotation (landmark depth, which detectors guess poorly on
// oblique or unshaded faces, plays no part in it). Scale and translation from
// the camera centres are a first guess that the caller may refine.
bool SimilarityFromViewPoses(const std::vector<ViewPose>& views, Sim3* head_from_world) {
  if (views.size() < 3) return false;
  std::vector<Eigen::Matrix3d> rotations;
  for (const auto& v : views) rotations.push_back(v.cam_from_head.linear().transpose() * v.cam_from_world.linear());
  auto chordal_mean = [&views](const std::vector<Eigen::Matrix3d>& rs, const std::vector<bool>& use) {
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < rs.size(); ++i)
      if (use[i]) sum += views[i].weight * rs[i];
    return NearestRotation(sum);
  };
  std::vector<bool> use(rotations.size(), true);
  Eigen::Matrix3d rotation = chordal_mean(rotations, use);
  for (int round = 0; round < 3; ++round) {
    std::vector<double> angles;
    for (const auto& r : rotations) angles.push_back(Eigen::AngleAxisd(rotation.transpose() * r).angle());
    std::vector<double> sorted = angles;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double limit = std::max(3.0 * sorted[sorted.size() / 2], 2.0 * 3.14159265358979323846 / 180.0);
    std::vector<bool> next(angles.size());
    int kept = 0;
    for (size_t i = 0; i < angles.size(); ++i) kept += next[i] = angles[i] <= limit && views[i].weight > 0;
    if (kept < 3) break;  // keep the last set whole: rotation, scale and translation from the same views
    use = next;
    rotation = chordal_mean(rotations, use);
  }
  // Scale and translation with the rotation fixed: least squares on the centres.
  Eigen::Vector3d mean_w = Eigen::Vector3d::Zero(), mean_h = Eigen::Vector3d::Zero();
  double n = 0;
  for (size_t i = 0; i < views.size(); ++i) {
    if (!use[i]) continue;
    mean_w += views[i].weight * views[i].cam_from_world.inverse().translation();
    mean_h += views[i].weight * views[i].cam_from_head.inverse().translation();
    n += views[i].weight;
  }
  if (!(n > 0)) return false;
  mean_w /= n;
  mean_h /= n;
  double num = 0, den = 0;
  for (size_t i = 0; i < views.size(); ++i) {
    if (!use[i]) continue;
    const Eigen::Vector3d w = rotation * (views[i].cam_from_world.inverse().translation() - mean_w);
    const Eigen::Vector3d h = views[i].cam_from_head.inverse().translation() - mean_h;
    num += views[i].weight * w.dot(h);
    den += views[i].weight * w.squaredNorm();
  }
  if (!(den > 0) || !(num > 0)) return false;
  head_from_world->rotation = rotation;
  head_from_world->scale = num / den;
  head_from_world->translation = mean_h - head_from_world->scale * (rotation * mean_w);
  return std::isfinite(head_from_world->scale) && head_from_world->translation.allFinite();
}

double Reprojection(const Observation& o, const Eigen::Vector3d& x) {
  const Eigen::Vector3d h = o.projection * x.homogeneous();
  return h.z() > 0 ? (h.head<2>() / h.z() - o.pixel).norm() : 1e9;
}

// Triangulates each landmark robustly: detections on oblique views can be far
// off, so hypotheses from pairs of views are scored by how many views agree
// within `max_px`, and the best is refined on its agreeing views alone.
// Returns iBUG index -> point.
std::map<int, Eigen::Vector3d> TriangulateLandmarks(const std::vector<std::vector<Observation>>& per_landmark,
                                                    double max_px) {
  std::map<int, Eigen::Vector3d> points;
  TriangulationOptions unrefined;
  unrefined.refine = false;
  for (int i = 0; i < 68; ++i) {
    const auto& obs = per_landmark[i];
    if (obs.size() < 2) continue;
    const size_t step = std::max<size_t>(1, obs.size() / 24);
    std::vector<size_t> best_inliers;
    for (size_t a = 0; a < obs.size(); a += step)
      for (size_t b = a + 1; b < obs.size(); b += step) {
        const TriangulationResult pair =
            TriangulatePoint({{obs[a].projection, obs[a].pixel, 1.0}, {obs[b].projection, obs[b].pixel, 1.0}}, unrefined);
        if (!pair.ok || pair.quality != TriangulationQuality::kGood) continue;
        std::vector<size_t> inliers;
        for (size_t k = 0; k < obs.size(); ++k)
          if (Reprojection(obs[k], pair.point) < max_px) inliers.push_back(k);
        if (inliers.size() > best_inliers.size()) best_inliers = inliers;
      }
    if (best_inliers.size() < 2) continue;
    std::vector<TriangulationView> views;
    for (size_t k : best_inliers) views.push_back({obs[k].projection, obs[k].pixel, 1.0});
    const TriangulationResult r = TriangulatePoint(views);
    if (r.ok && r.quality == TriangulationQuality::kGood && r.rms_px < max_px) points[i] = r.point;
  }
  return points;
}

// rms_mm and median_mm from residuals_mm (not empty).
void SummariseResiduals(AlignResult* r) {
  std::vector<double> sorted = r->residuals_mm;
  double sum = 0;
  for (double e : sorted) sum += e * e;
  r->rms_mm = std::sqrt(sum / sorted.size());
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  r->median_mm = sorted[sorted.size() / 2];
}

// Refines head_from_world by reprojection: the model's landmark points, carried
// into the world by the similarity, are compared with the detections in every
// view of the group (robust loss). Unlike a fit to triangulated landmarks, the
// noise stays in the images where it arises, so the scale is not diluted by
// the triangulation's poorly measured depths.
bool RefineByReprojection(const std::vector<std::vector<Observation>>& per_landmark,
                          const std::vector<Eigen::Vector3d>& model_points, const std::vector<int>& landmarks,
                          double robust_px, bool hold_scale, Sim3* head_from_world, double* median_px) {
  const Sim3 start = head_from_world->Inverse();
  double params[7];
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(start.rotation.data()), params);
  for (int i = 0; i < 3; ++i) params[3 + i] = start.translation[i];
  params[6] = std::log(start.scale);
  ceres::Problem problem;
  int count = 0;
  for (int i : landmarks)
    for (const auto& o : per_landmark[i]) {
      problem.AddResidualBlock(SimilarityReprojectionCost::Create(model_points[i], o.projection, o.pixel, 1.0),
                               new ceres::HuberLoss(robust_px), params);
      ++count;
    }
  if (count < 12) return false;
  // The rotation stays: landmark depth (what a free rotation would lean on)
  // is what detectors measure worst, on oblique or unshaded faces.
  // A scale the cameras know (a rig file in metres) stays too.
  problem.SetManifold(params, hold_scale ? new ceres::SubsetManifold(7, {0, 1, 2, 6})
                                         : new ceres::SubsetManifold(7, {0, 1, 2}));
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = 100;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  if (!summary.IsSolutionUsable()) return false;
  Sim3 world_from_head;
  ceres::AngleAxisToRotationMatrix(params, ceres::ColumnMajorAdapter3x3(world_from_head.rotation.data()));
  world_from_head.translation = Eigen::Vector3d(params[3], params[4], params[5]);
  world_from_head.scale = std::exp(params[6]);
  const Sim3 refined = world_from_head.Inverse();
  if (!std::isfinite(refined.scale) || !refined.rotation.allFinite() || !refined.translation.allFinite()) return false;
  std::vector<double> errors;
  for (int i : landmarks)
    for (const auto& o : per_landmark[i]) errors.push_back(Reprojection(o, world_from_head * model_points[i]));
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  *median_px = errors[errors.size() / 2];
  *head_from_world = refined;
  return true;
}

// Landmarks that name one point of the surface from any side: eye corners,
// brow ends and mouth corners are marked by the skin's texture; the nose tip
// and base need shading to be seen and may be rejected by RANSAC. The nose
// bridge and jaw follow the visible contour (another surface point in every
// view) and are left out.
const std::vector<int>& RigidLandmarks() {
  static const std::vector<int> rigid = {17, 21, 22, 26, 36, 39, 42, 45, 48, 54, 30, 33};
  return rigid;
}

// Every usable view with its landmarks and (world frame) its PnP head pose,
// grouped by time: one group for a still head seen by one moving camera (or
// head-pose cameras, whose head frame is shared), a group per frame when
// several cameras watch a moving head (`per_frame`).
std::map<int, std::vector<ViewPose>> CollectViewPoses(const AlignOptions& options, const IngestedCapture& capture,
                                                      const CameraSet& cameras,
                                                      const std::vector<Eigen::Vector3d>& model_points,
                                                      bool per_frame) {
  const bool head_frame = cameras.frame == "head";
  // A rig's views: head poses from the face mesh where a frame has it.
  std::vector<Eigen::Vector3d> mesh_points;
  if (per_frame && options.rig_view_poses == "mesh" &&
      !ReadMeshEmbedding(options.mesh_embedding, &mesh_points).ok())
    HF_LOG(Warning) << "align: no face mesh embedding at '" << options.mesh_embedding
                    << "'; the views' head poses come from their 68 landmarks";
  std::map<int, std::vector<ViewPose>> view_poses;
  for (const auto& cam : capture.cameras) {
    const CameraIntrinsics* in = cameras.FindCamera(cam.name);
    if (!in || in->fx <= 0) continue;
    for (const auto& f : cam.frames) {
      const CameraView* view = cameras.FindView(cam.name, f.index);
      if (!view || !view->registered || !f.landmarks) continue;
      std::vector<Eigen::Vector2d> undistorted;
      for (int i = 0; i < 68; ++i)
        undistorted.push_back(in->Undistort(Eigen::Vector2d((*f.landmarks)[i].x, (*f.landmarks)[i].y)));
      ViewPose v;
      v.camera = cam.name;
      v.cam_from_world = view->cam_from_world;
      const Eigen::Matrix<double, 3, 4> p = in->K() * view->cam_from_world.matrix().topRows<3>();
      for (int i = 0; i < 68; ++i) v.landmarks.push_back({p, undistorted[i]});
      // Landmark detectors are trained on near-frontal faces: on oblique views
      // their points drift. Note whether the view's head yaw (from PnP against
      // the model) is within the limit.
      if (!head_frame) {
        PnpResult pose;
        if (mesh_points.size() == f.mesh.size() && !f.mesh.empty()) {
          std::vector<Eigen::Vector2d> mesh;
          for (const cv::Point3f& p : f.mesh) mesh.push_back(in->Undistort(Eigen::Vector2d(p.x, p.y)));
          pose = SolvePnp(mesh_points, mesh, in->K());
        }
        if (!pose.ok) pose = SolvePnp(model_points, undistorted, in->K());
        if (!pose.ok) continue;
        const Eigen::Vector3d eye = pose.cam_from_object.inverse().translation();
        v.cam_from_head = pose.cam_from_object;
        v.frontal_by_pnp =
            std::abs(std::atan2(eye.x(), eye.z())) * 180.0 / 3.14159265358979323846 <= options.max_yaw_deg;
      }
      view_poses[per_frame ? f.index : 0].push_back(std::move(v));
    }
  }
  return view_poses;
}

// Head-pose cameras already live in the head frame: the transform is the
// identity. Residual of a landmark: its median distance (mm) from its viewing
// rays, which needs no parallax between frames.
Status MeasureHeadPoseCameras(const std::map<int, std::vector<ViewPose>>& view_poses,
                              const std::vector<Eigen::Vector3d>& model_points, const CameraSet& cameras,
                              AlignResult* result) {
  AlignResult r;
  for (int i : RigidLandmarks()) {
    std::vector<double> distances;
    for (const auto& [frame, views] : view_poses)
      for (const ViewPose& v : views) {
        const Observation& o = v.landmarks[i];
        const Eigen::Vector3d centre = ProjectionCentre(o.projection);
        const Eigen::Vector3d dir =
            o.projection.leftCols<3>().colPivHouseholderQr().solve(o.pixel.homogeneous()).normalized();
        const Eigen::Vector3d d = model_points[i] - centre;
        distances.push_back(1000.0 * (d - d.dot(dir) * dir).norm());
      }
    if (distances.empty()) continue;
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    r.landmarks_used.push_back(i);
    r.residuals_mm.push_back(distances[distances.size() / 2]);
    r.inlier.push_back(true);
  }
  if (r.landmarks_used.empty()) return Status::DataError("no frame has landmarks to measure the alignment with");
  SummariseResiduals(&r);
  r.cameras = cameras;
  r.message = "head-pose cameras: identity transform; residuals are distances from the landmarks' viewing rays";
  *result = std::move(r);
  return Status::Ok();
}

// The rigid landmarks triangulated from a group's views and matched to the
// model by Umeyama in RANSAC.
struct LandmarkFit {
  std::vector<int> used;
  Eigen::Matrix3Xd src, tgt;  // triangulated (world) and model (head) points
  SimilarityResult sim;
};

bool FitLandmarks(const AlignOptions& options, const std::vector<Eigen::Vector3d>& model_points,
                  const std::vector<std::vector<Observation>>& per_landmark, LandmarkFit* fit) {
  const auto points = TriangulateLandmarks(per_landmark, options.max_reprojection_px);
  fit->used.clear();
  for (int i : RigidLandmarks())
    if (points.count(i)) fit->used.push_back(i);
  if (fit->used.size() < 4) return false;
  fit->src.resize(3, Eigen::Index(fit->used.size()));
  fit->tgt.resize(3, Eigen::Index(fit->used.size()));
  for (size_t k = 0; k < fit->used.size(); ++k) {
    fit->src.col(Eigen::Index(k)) = points.at(fit->used[k]);
    fit->tgt.col(Eigen::Index(k)) = model_points[fit->used[k]];
  }
  // The world's unit is unknown before alignment: the RANSAC threshold
  // applies in the target (head) frame, metres.
  RansacOptions ransac;
  ransac.inlier_threshold = options.inlier_mm / 1000.0;
  fit->sim = EstimateSimilarityRansac(fit->src, fit->tgt, ransac);
  return true;
}

// Chooses the views again by where their cameras are, under the rotation so
// far, until the choice settles; then triangulates from those views. Keeps
// the first choice when too few views face the face.
void ChooseViewsByGeometry(const AlignOptions& options, const std::vector<Eigen::Vector3d>& model_points,
                           const std::vector<ViewPose>& views, bool per_frame, Sim3* from_views,
                           std::vector<std::vector<Observation>>* per_landmark, LandmarkFit* lf, int* views_used) {
  const Eigen::Vector3d face_centre = lf->src.rowwise().mean();
  const Sim3 first_choice = *from_views;
  std::vector<ViewPose> chosen;
  bool settled = false;
  // A fixed-point iteration: each round moves the rotation by the part of
  // the last move the detector does not see (unshaded orbits: about 0.7
  // of it), so settling takes some fifteen rounds there; each round is a
  // mean of rotations.
  constexpr int kMaxRounds = 60;
  for (int round = 0; round < kMaxRounds && !settled; ++round) {
    const std::vector<ViewPose> facing =
        ViewsFacing(views, from_views->rotation, face_centre, options.max_yaw_deg, options.max_elevation_deg);
    Sim3 next;
    if (!SimilarityFromViewPoses(facing, &next)) break;
    const double moved = Eigen::AngleAxisd(next.rotation.transpose() * from_views->rotation).angle();
    HF_LOG(Debug) << "align: view choice round " << round << ": " << facing.size() << " views, rotation moved "
                  << moved * 180 / M_PI << " deg";
    settled = moved < 1e-4;
    *from_views = next;
    chosen = facing;
  }
  if (!settled && !per_frame)
    HF_LOG(Warning) << "align: the choice of views did not settle in " << kMaxRounds << " rounds; using the last ("
                    << chosen.size() << " views)";
  // Too few views to surround the face (a rig's few fixed cameras, tens of
  // degrees apart): the window cannot be made even, and its mean follows
  // whichever view falls in or out; keep the first choice.
  constexpr size_t kMinFacingViews = 6;
  LandmarkFit refit;
  std::vector<std::vector<Observation>> chosen_landmarks = ByLandmark(chosen);
  if (chosen.size() >= kMinFacingViews && FitLandmarks(options, model_points, chosen_landmarks, &refit)) {
    *per_landmark = std::move(chosen_landmarks);
    *lf = refit;
    *views_used = static_cast<int>(chosen.size());
  } else {
    *from_views = first_choice;
  }
}

// The views fix the rotation; scale and translation come from the landmarks
// (their extent across the face is well measured even where their depth is
// not), by least squares with the rotation held. `lf.sim` becomes that
// similarity with its inliers.
void FitScaleWithRotationHeld(const AlignOptions& options, Sim3 from_views, LandmarkFit* lf) {
  const Eigen::Matrix3Xd& src = lf->src;
  const Eigen::Matrix3Xd& tgt = lf->tgt;
  SimilarityResult& sim = lf->sim;
  std::vector<int> fit_set = sim.inliers;
  if (!sim.ok || fit_set.size() < 3) {
    fit_set.resize(lf->used.size());
    for (size_t k = 0; k < lf->used.size(); ++k) fit_set[k] = static_cast<int>(k);
  }
  Eigen::Vector3d mean_w = Eigen::Vector3d::Zero(), mean_h = Eigen::Vector3d::Zero();
  for (int k : fit_set) {
    mean_w += src.col(k);
    mean_h += tgt.col(k);
  }
  mean_w /= static_cast<double>(fit_set.size());
  mean_h /= static_cast<double>(fit_set.size());
  double num = 0, den = 0;
  for (int k : fit_set) {
    const Eigen::Vector3d w = from_views.rotation * (src.col(k) - mean_w);
    num += w.dot(tgt.col(k) - mean_h);
    den += w.squaredNorm();
  }
  if (num > 0 && den > 0) {
    from_views.scale = num / den;
    from_views.translation = mean_h - from_views.scale * (from_views.rotation * mean_w);
  }
  // Inliers and residuals of the landmarks under the combined similarity.
  sim.ok = true;
  sim.tgt_from_src = from_views;
  sim.quality = SimilarityQuality::kGood;
  sim.inliers.clear();
  for (size_t k = 0; k < lf->used.size(); ++k)
    if ((tgt.col(k) - from_views * src.col(k)).norm() < options.inlier_mm / 1000.0)
      sim.inliers.push_back(static_cast<int>(k));
}

// The alignment from one group's views (false: too few landmarks, or no
// similarity); `per_landmark` the observations it used.
bool AlignGroup(const AlignOptions& options, const std::vector<Eigen::Vector3d>& model_points,
                const std::vector<ViewPose>& views, int frame, bool per_frame, AlignResult* r,
                std::vector<std::vector<Observation>>* per_landmark) {
  std::vector<ViewPose> frontal;
  for (const ViewPose& v : views)
    if (v.frontal_by_pnp) frontal.push_back(v);
  if (frontal.empty()) return false;
  *per_landmark = ByLandmark(frontal);
  LandmarkFit lf;
  if (!FitLandmarks(options, model_points, *per_landmark, &lf)) return false;
  Sim3 from_views;
  const bool use_views = options.method == "views" && SimilarityFromViewPoses(frontal, &from_views);
  int views_used = static_cast<int>(frontal.size());
  if (use_views && options.select_views == "geometry")
    ChooseViewsByGeometry(options, model_points, views, per_frame, &from_views, per_landmark, &lf, &views_used);
  if (use_views) FitScaleWithRotationHeld(options, from_views, &lf);
  if (!lf.sim.ok) return false;
  // Per view: the head's turn its own landmarks give (PnP) against where its
  // camera stands under the rotation found: detectors read turned faces as
  // nearly frontal (docs/benchmarks.md, the dome).
  if (GetLogLevel() <= LogLevel::kDebug) {
    auto yaw = [](const Eigen::Vector3d& d) { return std::atan2(d.x(), d.z()) * 180 / M_PI; };
    auto elevation = [](const Eigen::Vector3d& d) { return std::atan2(d.y(), std::hypot(d.x(), d.z())) * 180 / M_PI; };
    const Eigen::Vector3d face_centre = lf.src.rowwise().mean();
    for (const ViewPose& v : views) {
      const Eigen::Vector3d eye = v.cam_from_head.inverse().translation();
      const Eigen::Vector3d seen =
          lf.sim.tgt_from_src.rotation * (v.cam_from_world.inverse().translation() - face_centre);
      HF_LOG(Debug) << "align: frame " << frame << " " << v.camera << ": PnP yaw " << yaw(eye) << " elevation "
                    << elevation(eye) << (v.frontal_by_pnp ? " (frontal)" : "") << "; its camera at yaw " << yaw(seen)
                    << " elevation " << elevation(seen);
    }
  }
  *r = AlignResult();
  r->head_from_world = lf.sim.tgt_from_src;
  r->quality = lf.sim.quality;
  r->method = use_views ? "views" : "landmarks";
  r->views_used = use_views ? views_used : 0;
  r->landmarks_used = lf.used;
  r->reference_frame = per_frame ? frame : -1;
  for (size_t k = 0; k < lf.used.size(); ++k) {
    r->residuals_mm.push_back(1000.0 * (lf.tgt.col(k) - r->head_from_world * lf.src.col(k)).norm());
    r->points.push_back(lf.src.col(k));
    r->inlier.push_back(std::find(lf.sim.inliers.begin(), lf.sim.inliers.end(), static_cast<int>(k)) !=
                        lf.sim.inliers.end());
  }
  SummariseResiduals(r);
  return true;
}

// The landmarks' residuals and inliers under best.head_from_world.
void Rescore(const AlignOptions& options, const std::vector<Eigen::Vector3d>& model_points, AlignResult* best) {
  for (size_t k = 0; k < best->landmarks_used.size(); ++k) {
    best->residuals_mm[k] =
        1000.0 * (model_points[best->landmarks_used[k]] - best->head_from_world * best->points[k]).norm();
    best->inlier[k] = best->residuals_mm[k] < options.inlier_mm;
  }
  SummariseResiduals(best);
}

// Landmarks leave the head frame a degree or more off and take its scale from
// the mean face; thousands of points on the skin pin both. For a still head
// seen by one moving camera, the points of all its views. For several cameras
// watching a moving head, each instant's views see one face at once: the
// points of each instant keep their own head pose in the fit, which shares
// the identity and the scale (a few hundred points an instant on a rig's
// faces, too few alone), starting from each instant's own alignment
// (`instants`) at the reference instant's scale.
void ApplySurfaceFit(const AlignOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                     const FaceModel& model, const std::vector<Eigen::Vector3d>& model_points, bool per_frame,
                     const std::map<int, Sim3>& instants, AlignResult* best) {
  if (capture.cameras.empty()) {
    best->surface_note = "surface fit: the capture has no camera";
    return;
  }
  // Groups of views, the reference instant's first, then others spread
  // evenly over the capture up to surface_instants in all.
  std::vector<int> group_frames = {best->reference_frame};
  if (per_frame) {
    std::vector<int> others;
    for (const auto& [frame, pose] : instants)
      if (frame != best->reference_frame) others.push_back(frame);
    const int take = std::min(options.surface_instants - 1, static_cast<int>(others.size()));
    for (int k = 0; k < take; ++k) group_frames.push_back(others[size_t(k * int(others.size()) / take)]);
  }
  std::vector<std::vector<Eigen::Vector3d>> groups;
  std::vector<Sim3> starts;
  FacePointStats stats;
  Status fitted = Status::Ok();
  for (int frame : group_frames) {
    std::vector<FaceViewRef> views;
    for (const IngestedCamera& camera : capture.cameras)
      for (const IngestedFrame& f : camera.frames)
        if (per_frame ? f.index == frame : &camera == &capture.cameras[0]) views.push_back({camera.name, f.index});
    std::vector<Eigen::Vector3d> points;
    FacePointStats group_stats;
    fitted = TriangulateFacePoints(capture, cameras, views, FacePointOptions(), &points, &group_stats);
    if (!fitted.ok()) break;
    stats.views += group_stats.views;
    stats.pairs += group_stats.pairs;
    stats.points += group_stats.points;
    if (frame != best->reference_frame && points.empty()) continue;
    // Every instant at the reference's scale, about its own head origin.
    // Its own alignment is within a few degrees of the reference's turn.
    Sim3 start = frame == best->reference_frame ? best->head_from_world : instants.at(frame);
    const Eigen::Vector3d origin = start.Inverse() * Eigen::Vector3d::Zero();
    start.scale = best->head_from_world.scale;
    start.translation = -start.scale * (start.rotation * origin);
    groups.push_back(std::move(points));
    starts.push_back(start);
  }
  // The head frame is the reference instant's: its own points must pin its
  // pose (the other instants' pin the identity and the scale).
  constexpr size_t kFewestAtReference = 100;
  if (fitted.ok() && per_frame && (groups.empty() || groups[0].size() < kFewestAtReference))
    fitted = Status::DataError("surface fit: the reference instant's views give " +
                               std::to_string(groups.empty() ? 0 : groups[0].size()) +
                               " points on the face (need " + std::to_string(kFewestAtReference) + ")");
  SurfaceFitOptions fit;
  fit.noise_mm = options.surface_noise_mm;
  fit.hold_scale = cameras.metres_per_unit > 0;
  // A rig's cameras from COLMAP at one instant leave the landmarks' scale
  // 10-16 % off (its focal length from a few views), which the fit over
  // thousands of points mends (rig_8cam: to 3 %).
  if (per_frame) fit.max_scale_change = 0.25;
  SurfaceFitResult surface;
  best->face_points = stats.points;
  if (fitted.ok())
    HF_LOG(Info) << "align: " << stats.points << " points triangulated on the face from " << stats.pairs
                 << " pairs of " << stats.views << " views"
                 << (per_frame ? " at " + std::to_string(groups.size()) + " instants" : "");
  if (fitted.ok()) fitted = FitFaceSurfaceGroups(model, groups, fit, &starts, &surface);
  if (!fitted.ok()) {
    best->surface_note = fitted.message() + "; the landmarks' head frame is kept";
    HF_LOG(Warning) << "align: " << best->surface_note;
    return;
  }
  best->head_from_world = starts[0];
  best->method += "+surface";
  best->surface_points = surface.points;
  best->surface_median_mm = surface.median_mm;
  best->surface_turn_deg = surface.turn_deg;
  best->surface_scale_change = surface.scale_change;
  Rescore(options, model_points, best);
  HF_LOG(Info) << "align: surface fit on " << surface.points << " of " << stats.points
               << " points: turned the head frame " << surface.turn_deg << " deg and scaled it by "
               << 100 * surface.scale_change << "%; median distance " << surface.median_mm << " mm";
}

}  // namespace

Status RunAlign(const AlignOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                const FaceModel& model, AlignResult* result) {
  HF_RETURN_IF_ERROR(options.Check());
  if (model.landmarks_ibug68().size() != 68) return Status::InvalidArgument("the face model has no iBUG-68 landmarks");
  const bool head_frame = cameras.frame == "head";
  const bool per_frame = !head_frame && capture.cameras.size() > 1;
  const std::vector<Eigen::Vector3d> model_points = DetectorLandmarkPoints(model, options.landmark_embedding);
  const std::map<int, std::vector<ViewPose>> view_poses =
      CollectViewPoses(options, capture, cameras, model_points, per_frame);
  if (head_frame) return MeasureHeadPoseCameras(view_poses, model_points, cameras, result);

  AlignResult best;
  std::vector<std::vector<Observation>> best_observations;
  std::map<int, Sim3> instants;  // a rig's instants: each one's head frame from its own views
  bool found = false;
  for (const auto& [frame, views] : view_poses) {
    AlignResult r;
    std::vector<std::vector<Observation>> per_landmark;
    if (!AlignGroup(options, model_points, views, frame, per_frame, &r, &per_landmark)) continue;
    if (per_frame) instants[frame] = r.head_from_world;
    if (!found || r.median_mm < best.median_mm) {
      best = r;
      best_observations = per_landmark;
      found = true;
    }
    if (!per_frame) break;
  }
  if (!found)
    return Status::DataError("too few landmarks could be triangulated to align with the face model (need 4 rigid "
                             "landmarks seen in 2 or more registered views with enough parallax)");
  if (best.quality != SimilarityQuality::kGood)
    best.message = std::string("alignment quality: ") + SimilarityQualityName(best.quality);
  // The refinement reprojects every rigid landmark, triangulated or not (it
  // needs only their detections). Restricting it to the 3D fit's inliers was
  // tried: that set is chosen under the diluted scale, often a few landmarks
  // near the nose, and left the scale far worse determined; the Huber loss
  // tempers the detections that stray.
  // Cameras whose unit is known (a rig file that says it): the head frame
  // keeps it as its scale, about the head's origin; a face's size differs
  // from the mean face's by several percent, a calibrated rig's does not.
  const bool metric = cameras.metres_per_unit > 0;
  if (metric) {
    const Eigen::Vector3d origin = best.head_from_world.Inverse() * Eigen::Vector3d::Zero();
    HF_LOG(Info) << "align: the cameras' unit is " << cameras.metres_per_unit << " m: the head frame's scale "
                 << best.head_from_world.scale << " from the landmarks is replaced by it";
    best.head_from_world.scale = cameras.metres_per_unit;
    best.head_from_world.translation = -best.head_from_world.scale * (best.head_from_world.rotation * origin);
    best.method += "+unit";
    Rescore(options, model_points, &best);
  }
  if (options.refine == "reprojection") {
    double median_px = 0;
    if (RefineByReprojection(best_observations, model_points, RigidLandmarks(), options.refine_robust_px, metric,
                             &best.head_from_world, &median_px)) {
      best.method += "+reprojection";
      best.reprojection_median_px = median_px;
      Rescore(options, model_points, &best);
    }
  }
  best.landmarks_head_from_world = best.head_from_world;
  if (options.surface == "points" && per_frame && !options.rig_surface)
    best.surface_note = "surface fit: on several cameras only with --align-rig-surface";
  else if (options.surface == "points")
    ApplySurfaceFit(options, capture, cameras, model, model_points, per_frame, instants, &best);
  // A face is some 150 mm across: landmarks that miss the model by tens of
  // millimetres mean the cameras do not see one consistent head, whatever
  // COLMAP's registration count said.
  if (best.median_mm > options.max_residual_mm) {
    char text[640];
    std::snprintf(text, sizeof(text),
                  "the cameras do not agree on the face: landmarks triangulated from them miss the face model by a "
                  "median %.0f mm (limit %.0f mm%s). The reconstruction is probably wrong even where frames "
                  "registered; try calibrate with --max-features 8192, --matcher exhaustive, another --rig-instants (3 "
                  "where one instant was used: a dome's cameras), "
                  "a rig file (--mode rig) or --mode head-pose",
                  best.median_mm, options.max_residual_mm,
                  best.reprojection_median_px > 0
                      ? (", landmark reprojection " + std::to_string(int(std::lround(best.reprojection_median_px))) + " px").c_str()
                      : "");
    return Status::DataError(text);
  }
  best.cameras = ToHeadFrame(cameras, best.head_from_world);
  if (options.drop_misplaced) HF_RETURN_IF_ERROR(DropMisplacedViews(capture, &best));
  *result = std::move(best);
  return Status::Ok();
}

}  // namespace headforge
