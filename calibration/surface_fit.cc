#include "calibration/surface_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "core/log.h"
#include "core/mesh_renderer.h"
#include "core/statistics.h"

namespace headforge {
namespace {

// The fitting region's triangles and, per vertex, the region triangles around
// it and its neighbours (where the closest point of the surface is sought).
struct RegionMesh {
  std::vector<int> vertices;                  // region vertices that some region triangle uses
  std::vector<std::array<int, 3>> triangles;  // model vertex indices
  std::vector<std::vector<int>> nearby;       // per model vertex: region triangle indices
};

RegionMesh BuildRegionMesh(const FaceModel& model) {
  RegionMesh mesh;
  const int n = model.num_vertices();
  std::vector<bool> in_region(size_t(n), false);
  for (int v : model.fitting_vertices()) in_region[size_t(v)] = true;
  std::vector<std::vector<int>> around(static_cast<size_t>(n));
  for (int t = 0; t < model.num_triangles(); ++t) {
    const std::array<int, 3> tri = {model.triangles()(0, t), model.triangles()(1, t), model.triangles()(2, t)};
    if (!in_region[size_t(tri[0])] || !in_region[size_t(tri[1])] || !in_region[size_t(tri[2])]) continue;
    for (int v : tri) around[size_t(v)].push_back(static_cast<int>(mesh.triangles.size()));
    mesh.triangles.push_back(tri);
  }
  mesh.nearby.resize(size_t(n));
  for (int v = 0; v < n; ++v) {
    if (around[size_t(v)].empty()) continue;
    mesh.vertices.push_back(v);
    std::vector<int>& list = mesh.nearby[size_t(v)];
    for (int t : around[size_t(v)])
      for (int u : mesh.triangles[size_t(t)])
        list.insert(list.end(), around[size_t(u)].begin(), around[size_t(u)].end());
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  return mesh;
}

// The region's vertices bucketed in cubes of one pairing distance, for the
// nearest vertex within that distance.
class VertexGrid {
 public:
  VertexGrid(const Eigen::Matrix3Xd& shape, const std::vector<int>& vertices, double cell)
      : shape_(shape), cell_(cell) {
    low_ = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
    Eigen::Vector3d high = -low_;
    for (int v : vertices) {
      low_ = low_.cwiseMin(shape.col(v));
      high = high.cwiseMax(shape.col(v));
    }
    for (int k = 0; k < 3; ++k) size_[k] = std::max(1, int((high[k] - low_[k]) / cell) + 1);
    start_.assign(size_t(size_[0]) * size_[1] * size_[2] + 1, 0);
    for (int v : vertices) ++start_[size_t(Cell(shape.col(v))) + 1];
    for (size_t i = 1; i < start_.size(); ++i) start_[i] += start_[i - 1];
    order_.resize(vertices.size());
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (int v : vertices) order_[size_t(fill[size_t(Cell(shape.col(v)))]++)] = v;
  }

  // The nearest vertex within one cell's size of p, or -1.
  int Nearest(const Eigen::Vector3d& p) const {
    int best = -1;
    double best_d2 = cell_ * cell_;
    int at[3];
    for (int k = 0; k < 3; ++k) at[k] = int(std::floor((p[k] - low_[k]) / cell_));
    for (int x = at[0] - 1; x <= at[0] + 1; ++x) {
      if (x < 0 || x >= size_[0]) continue;
      for (int y = at[1] - 1; y <= at[1] + 1; ++y) {
        if (y < 0 || y >= size_[1]) continue;
        for (int z = at[2] - 1; z <= at[2] + 1; ++z) {
          if (z < 0 || z >= size_[2]) continue;
          const size_t c = (size_t(x) * size_[1] + y) * size_[2] + z;
          for (int i = start_[c]; i < start_[c + 1]; ++i) {
            const double d2 = (shape_.col(order_[size_t(i)]) - p).squaredNorm();
            if (d2 < best_d2) {
              best_d2 = d2;
              best = order_[size_t(i)];
            }
          }
        }
      }
    }
    return best;
  }

 private:
  int Cell(const Eigen::Vector3d& p) const {
    int at[3];
    for (int k = 0; k < 3; ++k) at[k] = std::clamp(int((p[k] - low_[k]) / cell_), 0, size_[k] - 1);
    return (at[0] * size_[1] + at[1]) * size_[2] + at[2];
  }

  const Eigen::Matrix3Xd& shape_;
  double cell_;
  Eigen::Vector3d low_;
  int size_[3];
  std::vector<int> start_, order_;
};

// One round's pairing of a group's points with the surface, its normal
// equations added to the whole fit's: the shared log scale at 0, the group's
// rotation and translation at `at`, the identity at the tail.
void AddGroup(const std::vector<Eigen::Vector3d>& world_points, const Sim3& pose, const Eigen::Matrix3Xd& shape,
              const RegionMesh& mesh, const VertexGrid& grid, const Eigen::MatrixXd& basis, double limit,
              double to_data, double noise, int at, Eigen::MatrixXd* normal_matrix, Eigen::VectorXd* gradient,
              std::vector<double>* distances) {
  const int modes = static_cast<int>(basis.cols());
  const int local = 7 + modes;
  Eigen::MatrixXd n_local = Eigen::MatrixXd::Zero(local, local);
  Eigen::VectorXd g_local = Eigen::VectorXd::Zero(local);
  Eigen::VectorXd j(local);
  for (const Eigen::Vector3d& p : world_points) {
    const Eigen::Vector3d h = pose * p;
    const int nearest = grid.Nearest(h);
    if (nearest < 0) continue;
    double best = limit;
    int best_t = -1;
    Eigen::Vector3d best_w = Eigen::Vector3d::Zero();
    for (int t : mesh.nearby[size_t(nearest)]) {
      const std::array<int, 3>& tri = mesh.triangles[size_t(t)];
      const Eigen::Vector3d w = ClosestBarycentric(h, shape.col(tri[0]), shape.col(tri[1]), shape.col(tri[2]));
      const double d = (h - (w[0] * shape.col(tri[0]) + w[1] * shape.col(tri[1]) + w[2] * shape.col(tri[2]))).norm();
      if (d < best) {
        best = d;
        best_t = t;
        best_w = w;
      }
    }
    if (best_t < 0) continue;
    const std::array<int, 3>& tri = mesh.triangles[size_t(best_t)];
    const Eigen::Vector3d a = shape.col(tri[0]), b = shape.col(tri[1]), c = shape.col(tri[2]);
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    const Eigen::Vector3d q = best_w[0] * a + best_w[1] * b + best_w[2] * c;
    const double r = n.dot(h - q);
    const Eigen::Vector3d arm = h - pose.translation;
    j(0) = arm.dot(n) - r;  // d(to_data * r) / d log scale, over to_data
    j.segment<3>(1) = arm.cross(n);
    j.segment<3>(4) = n;
    j.tail(modes) =
        -(n.transpose() * (best_w[0] * basis.middleRows(3 * tri[0], 3) + best_w[1] * basis.middleRows(3 * tri[1], 3) +
                           best_w[2] * basis.middleRows(3 * tri[2], 3)))
             .transpose();
    const double rd = to_data * r;
    const double w = std::abs(rd) <= noise ? 1.0 : noise / std::abs(rd);
    n_local.selfadjointView<Eigen::Lower>().rankUpdate(j, w * to_data * to_data);
    g_local += (w * to_data * rd) * j;
    distances->push_back(std::abs(rd) * 1000.0);
  }
  n_local = n_local.selfadjointView<Eigen::Lower>();
  // Scatter: local 0 -> 0, 1..6 -> at.., the identity -> the tail.
  const int total = static_cast<int>(gradient->size());
  std::vector<int> index(static_cast<size_t>(local), 0);
  index[0] = 0;
  for (int k = 0; k < 6; ++k) index[size_t(1 + k)] = at + k;
  for (int k = 0; k < modes; ++k) index[size_t(7 + k)] = total - modes + k;
  for (int a = 0; a < local; ++a) {
    (*gradient)(index[size_t(a)]) += g_local(a);
    for (int b = 0; b < local; ++b) (*normal_matrix)(index[size_t(a)], index[size_t(b)]) += n_local(a, b);
  }
}

}  // namespace

Status FitFaceSurface(const FaceModel& model, const std::vector<Eigen::Vector3d>& world_points,
                      const SurfaceFitOptions& options, Sim3* head_from_world, SurfaceFitResult* result) {
  std::vector<Sim3> poses = {*head_from_world};
  HF_RETURN_IF_ERROR(FitFaceSurfaceGroups(model, {world_points}, options, &poses, result));
  *head_from_world = poses[0];
  return Status::Ok();
}

Status FitFaceSurfaceGroups(const FaceModel& model, const std::vector<std::vector<Eigen::Vector3d>>& groups,
                            const SurfaceFitOptions& options, std::vector<Sim3>* head_from_world,
                            SurfaceFitResult* result) {
  if (model.fitting_vertices().empty())
    return Status::DataError("the face model has no fitting region (masks/fitting_vertices)");
  if (!(options.start_mm >= options.end_mm) || !(options.end_mm > 0) || !(options.noise_mm > 0) || options.rounds < 1 ||
      !(options.max_scale_change > 0))
    return Status::InvalidArgument("surface fit: the distances, noise, rounds and limits must be positive");
  if (groups.empty() || groups.size() != head_from_world->size())
    return Status::InvalidArgument("surface fit: one starting head frame per group of points");
  for (const Sim3& pose : *head_from_world)
    if (pose.scale != (*head_from_world)[0].scale)
      return Status::InvalidArgument("surface fit: the groups' head frames must share one scale");
  const RegionMesh mesh = BuildRegionMesh(model);
  const int modes = std::clamp(options.identity_modes, 0, model.num_identity());
  const Eigen::MatrixXd basis = model.identity_basis().leftCols(modes).cast<double>();

  // head = scale * rotation * world + translation, a rotation and translation
  // per group and one scale. Each round solves for a small change of them:
  // h -> exp(ds) * dR * (h - t) + t + dt, with the identity's change, by
  // Gauss-Newton on the point-to-plane distances.
  std::vector<Sim3> poses = *head_from_world;
  const double start_scale = poses[0].scale;
  Eigen::VectorXd alpha = Eigen::VectorXd::Zero(modes);
  const double noise = options.noise_mm / 1000.0;
  const int num_groups = static_cast<int>(groups.size());
  const int unknowns = 1 + 6 * num_groups + modes;  // log scale, rotations and translations, identity
  std::vector<double> last_distances;
  for (int round = 0; round < options.rounds; ++round) {
    const Eigen::Matrix3Xd shape = model.Identity(alpha.cast<float>()).cast<double>();
    // Distances in the points' units (at the starting scale): see the header.
    // The pairing distance too, or a shrinking head would gather more points.
    const double to_data = start_scale / poses[0].scale;
    const double limit = std::max(options.end_mm, options.start_mm * std::pow(0.85, round)) / 1000.0 / to_data;
    const VertexGrid grid(shape, mesh.vertices, limit);
    Eigen::MatrixXd normal_matrix = Eigen::MatrixXd::Zero(unknowns, unknowns);
    Eigen::VectorXd gradient = Eigen::VectorXd::Zero(unknowns);
    std::vector<double> distances;
    for (int g = 0; g < num_groups; ++g) {
      const size_t before = distances.size();
      AddGroup(groups[size_t(g)], poses[size_t(g)], shape, mesh, grid, basis, limit, to_data, noise, 1 + 6 * g,
               &normal_matrix, &gradient, &distances);
      // A group that pairs too few points keeps its pose this round.
      if (distances.size() - before < 12)
        for (int k = 0; k < 6; ++k) normal_matrix(1 + 6 * g + k, 1 + 6 * g + k) += 1.0;
    }
    HF_LOG(Debug) << "surface fit: round " << round << ": " << distances.size() << " points within "
                  << limit * to_data * 1000 << " mm, median " << (distances.empty() ? 0.0 : Median(distances)) << " mm";
    // The first rounds may pair fewer points while the fit pulls the face
    // onto them (the prior keeps the identity determined); the last one must
    // pair min_points.
    const int fewest_early = 3 * (1 + 6 * num_groups);  // three times the frames' unknowns
    const bool last = round + 1 == options.rounds;
    if (static_cast<int>(distances.size()) < (last ? options.min_points : fewest_early))
      return Status::DataError("surface fit: " + std::to_string(distances.size()) +
                               " reconstructed points lie on the face (need " + std::to_string(options.min_points) +
                               ")");
    last_distances = distances;
    normal_matrix /= noise * noise;
    gradient /= noise * noise;
    normal_matrix.bottomRightCorner(modes, modes).diagonal().array() += 1.0;
    gradient.tail(modes) += alpha;
    if (options.hold_scale) {
      normal_matrix.row(0).setZero();
      normal_matrix.col(0).setZero();
      normal_matrix(0, 0) = 1.0;
      gradient(0) = 0.0;
    }
    const Eigen::VectorXd step = -normal_matrix.ldlt().solve(gradient);
    if (!step.allFinite()) return Status::DataError("surface fit: the normal equations are singular");
    for (int g = 0; g < num_groups; ++g) {
      Sim3& pose = poses[size_t(g)];
      const Eigen::Vector3d turn = step.segment<3>(1 + 6 * g);
      pose.scale *= std::exp(step(0));
      if (turn.norm() > 0) pose.rotation = Eigen::AngleAxisd(turn.norm(), turn.normalized()) * pose.rotation;
      pose.translation += step.segment<3>(4 + 6 * g);
    }
    alpha += step.tail(modes);
  }
  // The change in the first group's head frame: head_fitted = change * head_start.
  const Eigen::AngleAxisd change(poses[0].rotation * (*head_from_world)[0].rotation.transpose());
  const double turn_deg = change.angle() * 180.0 / M_PI;
  const double scale_change = poses[0].scale / start_scale - 1.0;
  if (turn_deg > options.max_turn_deg)
    return Status::DataError("surface fit: the face's points would turn the head frame by " +
                             std::to_string(int(std::lround(turn_deg))) + " deg (limit " +
                             std::to_string(int(options.max_turn_deg)) + ")");
  if (std::abs(scale_change) > options.max_scale_change)
    return Status::DataError("surface fit: the face's points would scale the head frame by " +
                             std::to_string(int(std::lround(100 * scale_change))) + "% (limit " +
                             std::to_string(int(std::lround(100 * options.max_scale_change))) + "%)");
  SurfaceFitResult out;
  out.points = static_cast<int>(last_distances.size());
  out.median_mm = Median(last_distances);
  out.turn_deg = turn_deg;
  out.turn_xyz_deg = change.axis() * turn_deg;
  out.scale_change = scale_change;
  out.identity = alpha;
  *head_from_world = poses;
  *result = out;
  return Status::Ok();
}

}  // namespace headforge
