#include "calibration/triangulation.h"

#include <Eigen/SVD>
#include <cmath>

#include "calibration/reprojection_cost.h"

namespace headforge {

const char* TriangulationQualityName(TriangulationQuality q) {
  switch (q) {
    case TriangulationQuality::kGood: return "good";
    case TriangulationQuality::kLowParallax: return "low-parallax";
    case TriangulationQuality::kFailed: return "failed";
  }
  return "failed";
}

Eigen::Vector3d ProjectionCentre(const Eigen::Matrix<double, 3, 4>& p) {
  return -p.leftCols<3>().colPivHouseholderQr().solve(p.col(3));
}

namespace {

double Depth(const Eigen::Matrix<double, 3, 4>& p, const Eigen::Vector3d& x) {
  // Sign of the third coordinate, corrected for det(M) (P may be scaled by -1).
  const double w = p.row(2).head<3>().dot(x) + p(2, 3);
  return w * (p.leftCols<3>().determinant() > 0 ? 1.0 : -1.0);
}

double ReprojectionRms(const std::vector<TriangulationView>& views, const Eigen::Vector3d& x) {
  double sum = 0;
  for (const auto& v : views) {
    const Eigen::Vector3d h = v.projection * x.homogeneous();
    sum += (h.head<2>() / h.z() - v.pixel).squaredNorm();
  }
  return std::sqrt(sum / static_cast<double>(views.size()));
}

}  // namespace

TriangulationResult TriangulatePoint(const std::vector<TriangulationView>& views,
                                     const TriangulationOptions& options) {
  TriangulationResult r;
  if (views.size() < 2) {
    r.message = "need at least 2 views, got " + std::to_string(views.size());
    return r;
  }
  for (const auto& v : views)
    if (!v.projection.allFinite() || !v.pixel.allFinite()) {
      r.message = "non-finite camera or observation";
      return r;
    }
  // DLT, each row normalised so views of different scale count alike.
  Eigen::MatrixXd a(2 * views.size(), 4);
  for (size_t i = 0; i < views.size(); ++i) {
    const auto& p = views[i].projection;
    Eigen::RowVector4d r0 = views[i].pixel.x() * p.row(2) - p.row(0);
    Eigen::RowVector4d r1 = views[i].pixel.y() * p.row(2) - p.row(1);
    a.row(2 * i) = views[i].weight * r0 / std::max(1e-300, r0.norm());
    a.row(2 * i + 1) = views[i].weight * r1 / std::max(1e-300, r1.norm());
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  // The ray angles decide whether depth is observable at all.
  std::vector<Eigen::Vector3d> centres;
  for (const auto& v : views) centres.push_back(ProjectionCentre(v.projection));
  const double scale = h.head<3>().norm();
  if (!(std::abs(h[3]) > 1e-12 * scale)) {
    r.message = "rays are parallel: the point is at infinity";
    return r;
  }
  Eigen::Vector3d x = h.head<3>() / h[3];
  if (!x.allFinite()) {
    r.message = "no finite intersection of the rays";
    return r;
  }
  if (options.refine) {
    ceres::Problem problem;
    double point[3] = {x.x(), x.y(), x.z()};
    for (const auto& v : views)
      problem.AddResidualBlock(PointReprojectionCost::Create(v.projection, v.pixel, v.weight),
                               new ceres::CauchyLoss(options.robust_scale_px), point);
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::DENSE_QR;
    solver.max_num_iterations = 50;
    solver.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(solver, &problem, &summary);
    const Eigen::Vector3d refined(point[0], point[1], point[2]);
    if (refined.allFinite() && summary.IsSolutionUsable() && ReprojectionRms(views, refined) <= ReprojectionRms(views, x) * 1.5 + 1e-9)
      x = refined;
  }
  int in_front = 0;
  for (const auto& v : views) in_front += Depth(v.projection, x) > 0;
  if (in_front < 2) {
    r.message = "the point lies behind the cameras";
    return r;
  }
  double max_angle = 0;
  for (size_t i = 0; i < centres.size(); ++i)
    for (size_t j = i + 1; j < centres.size(); ++j) {
      const Eigen::Vector3d a_ray = (x - centres[i]).normalized(), b_ray = (x - centres[j]).normalized();
      max_angle = std::max(max_angle, std::acos(std::clamp(a_ray.dot(b_ray), -1.0, 1.0)));
    }
  r.ok = true;
  r.point = x;
  r.max_angle_deg = max_angle * 180.0 / 3.14159265358979323846;
  r.rms_px = ReprojectionRms(views, x);
  r.quality = r.max_angle_deg < options.min_angle_deg ? TriangulationQuality::kLowParallax : TriangulationQuality::kGood;
  if (r.quality == TriangulationQuality::kLowParallax)
    r.message = "rays meet at " + std::to_string(r.max_angle_deg) + " degrees: depth poorly determined";
  return r;
}

}  // namespace headforge
