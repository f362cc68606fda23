#include "calibration/align.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>

#include "calibration/pnp.h"
#include "calibration/triangulation.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {

Status AlignOptions::Check() const {
  if (!(inlier_mm > 0)) return Status::InvalidArgument("--inlier-mm must be positive");
  if (!(max_reprojection_px > 0)) return Status::InvalidArgument("--max-reprojection must be positive");
  if (!(max_yaw_deg > 0)) return Status::InvalidArgument("--max-yaw must be positive");
  return Status::Ok();
}

void AddAlignOptions(OptionSet* o, AlignOptions* a) {
  o->Add("align.inlier_mm", &a->inlier_mm, "RANSAC inlier threshold for landmark pairs, millimetres.", "inlier-mm");
  o->Add("align.max_reprojection_px", &a->max_reprojection_px,
         "Drop triangulated landmarks that reproject worse than this (px).", "max-reprojection");
  o->Add("align.max_yaw_deg", &a->max_yaw_deg,
         "Use landmarks only from views whose head yaw is within this many degrees of frontal.", "max-yaw");
}

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

// Removes lens distortion from a pixel (fixed-point iteration on the normalised point).
Eigen::Vector2d UndistortPixel(const CameraIntrinsics& c, const Eigen::Vector2d& px) {
  const Eigen::Vector2d xd((px.x() - c.cx) / c.fx, (px.y() - c.cy) / c.fy);
  Eigen::Vector2d x = xd;
  for (int i = 0; i < 20; ++i) {
    const double r2 = x.squaredNorm();
    const double radial = 1 + c.k1 * r2 + c.k2 * r2 * r2;
    const Eigen::Vector2d tangential(2 * c.p1 * x.x() * x.y() + c.p2 * (r2 + 2 * x.x() * x.x()),
                                     c.p1 * (r2 + 2 * x.y() * x.y()) + 2 * c.p2 * x.x() * x.y());
    x = (xd - tangential) / radial;
  }
  return Eigen::Vector2d(c.fx * x.x() + c.cx, c.fy * x.y() + c.cy);
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

}  // namespace

Status RunAlign(const AlignOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                const FaceModel& model, AlignResult* result) {
  HF_RETURN_IF_ERROR(options.Check());
  if (model.landmarks_ibug68().size() != 68) return Status::InvalidArgument("the face model has no iBUG-68 landmarks");
  const bool head_frame = cameras.frame == "head";
  // Observations grouped by time: one group for a still head seen by one moving
  // camera (or head-pose cameras, whose head frame is shared), a group per frame
  // when several cameras watch a moving head.
  const bool per_frame = !head_frame && capture.cameras.size() > 1;
  std::vector<Eigen::Vector3d> model_points;
  for (int v : model.landmarks_ibug68()) model_points.push_back(model.neutral().col(v).cast<double>());
  std::map<int, std::vector<std::vector<Observation>>> groups;
  for (const auto& cam : capture.cameras) {
    const CameraIntrinsics* in = cameras.FindCamera(cam.name);
    if (!in || in->fx <= 0) continue;
    for (const auto& f : cam.frames) {
      const CameraView* view = cameras.FindView(cam.name, f.index);
      if (!view || !view->registered || !f.landmarks) continue;
      std::vector<Eigen::Vector2d> undistorted;
      for (int i = 0; i < 68; ++i)
        undistorted.push_back(UndistortPixel(*in, Eigen::Vector2d((*f.landmarks)[i].x, (*f.landmarks)[i].y)));
      // Landmark detectors are trained on near-frontal faces: on oblique views
      // their points drift. Keep views whose head yaw (from PnP against the
      // model) is within the limit.
      if (!head_frame) {
        const PnpResult pose = SolvePnp(model_points, undistorted, in->K());
        if (!pose.ok) continue;
        const Eigen::Vector3d eye = pose.cam_from_object.inverse().translation();
        if (std::abs(std::atan2(eye.x(), eye.z())) * 180.0 / 3.14159265358979323846 > options.max_yaw_deg) continue;
      }
      auto& group = groups[per_frame ? f.index : 0];
      group.resize(68);
      const Eigen::Matrix<double, 3, 4> p = in->K() * view->cam_from_world.matrix().topRows<3>();
      for (int i = 0; i < 68; ++i) group[i].push_back({p, undistorted[i]});
    }
  }
  // Landmarks that name one point of the surface from any side: eye corners,
  // brow ends and mouth corners are marked by the skin's texture; the nose tip
  // and base need shading to be seen and may be rejected by RANSAC. The nose
  // bridge and jaw follow the visible contour (another surface point in every
  // view) and are left out.
  std::vector<int> rigid = {17, 21, 22, 26, 36, 39, 42, 45, 48, 54, 30, 33};

  if (head_frame) {
    // Head-pose cameras already live in the head frame: the transform is the
    // identity. Residual of a landmark: its median distance (mm) from its
    // viewing rays, which needs no parallax between frames.
    AlignResult r;
    for (int i : rigid) {
      std::vector<double> distances;
      for (const auto& [frame, per_landmark] : groups)
        for (const auto& o : per_landmark[i]) {
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
    std::vector<double> sorted = r.residuals_mm;
    double sum = 0;
    for (double e : sorted) sum += e * e;
    r.rms_mm = std::sqrt(sum / sorted.size());
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    r.median_mm = sorted[sorted.size() / 2];
    r.cameras = cameras;
    r.message = "head-pose cameras: identity transform; residuals are distances from the landmarks' viewing rays";
    *result = std::move(r);
    return Status::Ok();
  }

  AlignResult best;
  bool found = false;
  for (const auto& [frame, per_landmark] : groups) {
    const auto points = TriangulateLandmarks(per_landmark, options.max_reprojection_px);
    std::vector<int> used;
    for (int i : rigid)
      if (points.count(i)) used.push_back(i);
    if (used.size() < 4) continue;
    Eigen::Matrix3Xd src(3, used.size()), tgt(3, used.size());
    for (size_t k = 0; k < used.size(); ++k) {
      src.col(k) = points.at(used[k]);
      tgt.col(k) = model_points[used[k]];
    }
    // The world's unit is unknown before alignment: the RANSAC threshold
    // applies in the target (head) frame, metres.
    RansacOptions ransac;
    ransac.inlier_threshold = options.inlier_mm / 1000.0;
    const SimilarityResult sim = EstimateSimilarityRansac(src, tgt, ransac);
    if (!sim.ok) continue;
    AlignResult r;
    r.head_from_world = sim.tgt_from_src;
    r.quality = sim.quality;
    r.landmarks_used = used;
    r.reference_frame = per_frame ? frame : -1;
    std::vector<double> sorted;
    double sum = 0;
    for (size_t k = 0; k < used.size(); ++k) {
      const double e = 1000.0 * (tgt.col(k) - r.head_from_world * src.col(k)).norm();
      r.residuals_mm.push_back(e);
      r.points.push_back(src.col(k));
      r.inlier.push_back(std::find(sim.inliers.begin(), sim.inliers.end(), static_cast<int>(k)) != sim.inliers.end());
      sorted.push_back(e);
      sum += e * e;
    }
    r.rms_mm = std::sqrt(sum / used.size());
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    r.median_mm = sorted[sorted.size() / 2];
    if (!found || r.median_mm < best.median_mm) {
      best = r;
      found = true;
    }
    if (!per_frame) break;
  }
  if (!found)
    return Status::DataError("too few landmarks could be triangulated to align with the face model (need 4 rigid "
                             "landmarks seen in 2 or more registered views with enough parallax)");
  best.cameras = ToHeadFrame(cameras, best.head_from_world);
  if (best.quality != SimilarityQuality::kGood)
    best.message = std::string("alignment quality: ") + SimilarityQualityName(best.quality);
  *result = std::move(best);
  return Status::Ok();
}

Status WriteAlignment(const AlignResult& r, const fs::path& path) {
  nlohmann::json residuals = nlohmann::json::array();
  for (size_t k = 0; k < r.landmarks_used.size(); ++k)
    residuals.push_back({{"landmark", r.landmarks_used[k]}, {"residual_mm", r.residuals_mm[k]}, {"inlier", static_cast<bool>(r.inlier[k])}});
  nlohmann::json rotation = nlohmann::json::array(), matrix = nlohmann::json::array();
  for (int i = 0; i < 3; ++i)
    rotation.push_back({r.head_from_world.rotation(i, 0), r.head_from_world.rotation(i, 1), r.head_from_world.rotation(i, 2)});
  const Eigen::Matrix4d m = r.head_from_world.Matrix();
  for (int i = 0; i < 4; ++i) matrix.push_back({m(i, 0), m(i, 1), m(i, 2), m(i, 3)});
  const nlohmann::json j = {
      {"version", 1},
      {"head_from_world", {{"scale", r.head_from_world.scale}, {"rotation", rotation},
                           {"translation", {r.head_from_world.translation.x(), r.head_from_world.translation.y(), r.head_from_world.translation.z()}},
                           {"matrix", matrix}}},
      {"quality", SimilarityQualityName(r.quality)},
      {"reference_frame", r.reference_frame},
      {"rms_mm", r.rms_mm},
      {"median_mm", r.median_mm},
      {"residuals", residuals},
      {"cameras", "cameras_head.json"},
      {"message", r.message}};
  return WriteJsonAtomic(path, j, 1);
}

}  // namespace headforge
