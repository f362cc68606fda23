#include "reconstruction/pose_identity.h"

#include <Eigen/Dense>
#include <cmath>

namespace headforge {

Status ImitateRigidMotions(const FaceModel& model, int modes, const std::string& points,
                           std::vector<RigidImitation>* rows) {
  if (modes < 1 || modes > model.num_identity())
    return Status::InvalidArgument("identity modes must be between 1 and the model's " +
                                   std::to_string(model.num_identity()));
  std::vector<int> vertices;
  if (points == "landmarks") {
    vertices = model.landmarks_ibug68();
    if (vertices.empty()) return Status::InvalidArgument("the face model has no landmark vertices");
  } else if (points == "all") {
    for (int v = 0; v < model.num_vertices(); ++v) vertices.push_back(v);
  } else if (const FaceModel::Region* r = model.FindRegion(points)) {
    for (int v = r->first_vertex; v <= r->last_vertex; ++v) vertices.push_back(v);
  } else {
    return Status::InvalidArgument("unknown point set '" + points + "': landmarks, all, or a region of the model");
  }
  const int n = static_cast<int>(vertices.size());
  if (n < 3) return Status::InvalidArgument("the point set has fewer than three vertices");
  Eigen::MatrixXd basis(3 * n, modes);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    basis.middleRows(3 * i, 3) = model.identity_basis().block(3 * vertices[i], 0, 3, modes).cast<double>();
    centre += model.neutral().col(vertices[i]).cast<double>();
  }
  centre /= n;
  // Rotations and scale are imitated by the modes together with a free
  // translation (a fit moves the head too); translations by the modes alone.
  Eigen::MatrixXd with_translation(3 * n, modes + 3);
  with_translation.leftCols(modes) = basis;
  for (int i = 0; i < n; ++i) with_translation.block(3 * i, modes, 3, 3).setIdentity();
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr_modes(basis), qr_moving(with_translation);
  const char* names[] = {"pitch (x)", "yaw (y)", "roll (z)", "along x", "along y", "along z", "scale"};
  rows->clear();
  for (int m = 0; m < 7; ++m) {
    Eigen::VectorXd d(3 * n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = model.neutral().col(vertices[i]).cast<double>() - centre;
      Eigen::Vector3d move;
      if (m < 3)
        move = (M_PI / 180.0) * Eigen::Vector3d::Unit(m).cross(p);  // 1 degree, small-angle
      else if (m < 6)
        move = 1e-3 * Eigen::Vector3d::Unit(m - 3);
      else
        move = 0.01 * p;
      d.segment<3>(3 * i) = move;
    }
    const bool translation = m >= 3 && m < 6;
    const Eigen::VectorXd x = translation ? Eigen::VectorXd(qr_modes.solve(d)) : Eigen::VectorXd(qr_moving.solve(d));
    const Eigen::VectorXd imitated = translation ? Eigen::VectorXd(basis * x) : Eigen::VectorXd(with_translation * x);
    RigidImitation row;
    row.motion = names[m];
    row.unit = m < 3 ? "1 deg" : (m < 6 ? "1 mm" : "1 %");
    row.shared = imitated.norm() / d.norm();
    row.alpha_norm = x.head(modes).norm();
    row.motion_mm = 1e3 * d.norm() / std::sqrt(double(n));
    row.left_over_mm = 1e3 * (d - imitated).norm() / std::sqrt(double(n));
    rows->push_back(row);
  }
  return Status::Ok();
}

}  // namespace headforge
