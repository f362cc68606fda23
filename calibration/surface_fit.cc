#include "calibration/surface_fit.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "core/log.h"
#include "core/mesh_renderer.h"
#include "core/statistics.h"

namespace headforge {
Status FitFaceSurface(const FaceModel& model, const std::vector<Eigen::Vector3d>& world_points,
                      const SurfaceFitOptions& options, Sim3* head_from_world, SurfaceFitResult* result) {
  const std::vector<int>& region = model.fitting_vertices();
  if (region.empty()) return Status::DataError("the face model has no fitting region (masks/fitting_vertices)");
  if (!(options.start_mm >= options.end_mm) || !(options.end_mm > 0) || !(options.robust_mm > 0) ||
      !(options.identity_prior_mm2 > 0) || options.rounds < 1)
    return Status::InvalidArgument("surface fit: the distances, prior and rounds must be positive");
  const int modes = std::clamp(options.identity_modes, 0, model.num_identity());
  const int n_region = static_cast<int>(region.size());
  // The region's rows of the identity basis, in double.
  Eigen::MatrixXd basis(3 * n_region, modes);
  for (int i = 0; i < n_region; ++i)
    basis.middleRows(3 * i, 3) = model.identity_basis().block(3 * region[i], 0, 3, modes).cast<double>();

  // The rotation is head_from_world's turned about the head frame's vertical
  // axis (yaw); pitch and roll stay exactly.
  Sim3 pose = *head_from_world;
  double yaw = 0;  // radians
  auto turned = [&](double angle) {
    return Eigen::Matrix3d(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()) * head_from_world->rotation);
  };
  Eigen::VectorXd alpha = Eigen::VectorXd::Zero(modes);
  const double prior = options.identity_prior_mm2 * 1e-6;  // m^2 per squared standard deviation
  const int unknowns = 4 + modes;                          // yaw, translation, identity
  std::vector<double> last_distances;
  for (int round = 0; round < options.rounds; ++round) {
    const Eigen::Matrix3Xf shape = model.Identity(alpha.cast<float>());
    const Eigen::Matrix3Xd normals = VertexNormals(shape, model.triangles()).cast<double>();
    Eigen::Matrix3Xd surface(3, n_region);
    for (int i = 0; i < n_region; ++i) surface.col(i) = shape.col(region[i]).cast<double>();
    const double limit = std::max(options.end_mm, options.start_mm * std::pow(0.85, round)) / 1000.0;
    const Eigen::Vector3d low = surface.rowwise().minCoeff().array() - limit;
    const Eigen::Vector3d high = surface.rowwise().maxCoeff().array() + limit;

    Eigen::MatrixXd normal_matrix = Eigen::MatrixXd::Zero(unknowns, unknowns);
    Eigen::VectorXd gradient = Eigen::VectorXd::Zero(unknowns);
    std::vector<double> distances;
    for (const Eigen::Vector3d& p : world_points) {
      const Eigen::Vector3d h = pose * p;
      if ((h.array() < low.array()).any() || (h.array() > high.array()).any()) continue;
      int nearest = -1;
      double best = limit * limit;
      for (int i = 0; i < n_region; ++i) {
        const double d = (surface.col(i) - h).squaredNorm();
        if (d < best) {
          best = d;
          nearest = i;
        }
      }
      if (nearest < 0) continue;
      const Eigen::Vector3d n = normals.col(region[nearest]);
      const double r = n.dot(h - surface.col(nearest));
      // d r / d yaw = ((h - t) x n) . y.
      Eigen::VectorXd j(unknowns);
      j(0) = (h - pose.translation).cross(n).y();
      j.segment<3>(1) = n;
      j.tail(modes) = -(n.transpose() * basis.middleRows(3 * nearest, 3)).transpose();
      const double w = std::abs(r) <= options.robust_mm / 1000.0 ? 1.0 : options.robust_mm / 1000.0 / std::abs(r);
      normal_matrix.selfadjointView<Eigen::Lower>().rankUpdate(j, w);
      gradient += w * r * j;
      distances.push_back(std::abs(r) * 1000.0);
    }
    HF_LOG(Debug) << "surface fit: round " << round << ": " << distances.size() << " points within "
                  << limit * 1000 << " mm, median " << (distances.empty() ? 0.0 : Median(distances)) << " mm";
    // The first rounds may pair few points while the fit pulls the face onto
    // them (the prior keeps the identity determined); the last one must pair
    // min_points.
    constexpr int kFewestEarly = 12;  // three times the pose's unknowns
    const bool last = round + 1 == options.rounds;
    if (static_cast<int>(distances.size()) < (last ? options.min_points : kFewestEarly))
      return Status::DataError("surface fit: " + std::to_string(distances.size()) +
                               " reconstructed points lie on the face (need " + std::to_string(options.min_points) +
                               ")");
    last_distances = distances;
    normal_matrix = normal_matrix.selfadjointView<Eigen::Lower>();
    normal_matrix.bottomRightCorner(modes, modes).diagonal().array() += prior;
    gradient.tail(modes) += prior * alpha;
    normal_matrix.diagonal().array() += 1e-12;
    const Eigen::VectorXd step = -normal_matrix.ldlt().solve(gradient);
    if (!step.allFinite()) return Status::DataError("surface fit: the normal equations are singular");
    yaw += step(0);
    pose.rotation = turned(yaw);
    pose.translation += step.segment<3>(1);
    alpha += step.tail(modes);
  }
  if (std::abs(yaw) * 180.0 / M_PI > options.max_turn_deg)
    return Status::DataError("surface fit: the face's points would turn the head frame by " +
                             std::to_string(int(std::lround(std::abs(yaw) * 180.0 / M_PI))) + " deg (limit " +
                             std::to_string(int(options.max_turn_deg)) + ")");
  SurfaceFitResult out;
  out.points = static_cast<int>(last_distances.size());
  out.median_mm = Median(last_distances);
  out.yaw_deg = yaw * 180.0 / M_PI;
  out.identity = alpha;
  *head_from_world = pose;
  *result = out;
  return Status::Ok();
}

}  // namespace headforge
