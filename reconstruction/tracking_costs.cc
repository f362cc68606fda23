#include "reconstruction/tracking_costs.h"

namespace headforge {

LandmarkReprojectionCost::LandmarkReprojectionCost(const LandmarkBasis& basis, int landmark,
                                                   const TrackingCamera& camera, const Eigen::Vector2d& pixel,
                                                   double weight)
    : base_(basis.base.col(landmark)),
      identity_(basis.identity[landmark]),
      expression_(basis.expression[landmark]),
      camera_(camera),
      pixel_(pixel),
      weight_(weight) {
  set_num_residuals(2);
  *mutable_parameter_block_sizes() = {3, 3, int(identity_.cols()), int(expression_.cols()), 1};
}

bool LandmarkReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                        double** jacobians) const {
  const double* rotation = parameters[0];
  const double* translation = parameters[1];
  const double focal_scale = parameters[4][0];
  const Eigen::Vector3d x = base_ + identity_ * Eigen::Map<const Eigen::VectorXd>(parameters[2], identity_.cols()) +
                            expression_ * Eigen::Map<const Eigen::VectorXd>(parameters[3], expression_.cols());
  // The rotated point and its derivatives with respect to the angle-axis
  // vector (columns 0-2) and the point (3-5), in one pass of dual numbers.
  using Jet6 = ceres::Jet<double, 6>;
  Jet6 angle_axis[3], point[3], moved[3];
  for (int d = 0; d < 3; ++d) {
    angle_axis[d] = Jet6(rotation[d], d);
    point[d] = Jet6(x[d], 3 + d);
  }
  ceres::AngleAxisRotatePoint(angle_axis, point, moved);
  Eigen::Vector3d q;
  Eigen::Matrix<double, 3, 6> dmoved;
  for (int d = 0; d < 3; ++d) {
    q[d] = moved[d].a + translation[d];
    dmoved.row(d) = moved[d].v.transpose();
  }
  Eigen::Vector3d p = camera_.rotation * q + camera_.translation;
  p.z() += (focal_scale - 1.0) * camera_.translation.z();
  // A landmark at or behind the camera has no pixel: reject the step.
  if (!(p.z() > 1e-6)) return false;
  const double u = p.x() / p.z(), v = p.y() / p.z();
  const double fx = focal_scale * camera_.fx, fy = focal_scale * camera_.fy;
  residuals[0] = weight_ * (fx * u + camera_.cx - pixel_.x());
  residuals[1] = weight_ * (fy * v + camera_.cy - pixel_.y());
  if (jacobians == nullptr) return true;

  using RowMajor2 = Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Matrix<double, 2, 3> dr_dp;
  dr_dp << weight_ * fx / p.z(), 0, -weight_ * fx * u / p.z(),  //
      0, weight_ * fy / p.z(), -weight_ * fy * v / p.z();
  const Eigen::Matrix<double, 2, 3> dr_dq = dr_dp * camera_.rotation;
  const Eigen::Matrix<double, 2, 3> dr_dx = dr_dq * dmoved.rightCols<3>();
  if (jacobians[0]) Eigen::Map<RowMajor2>(jacobians[0], 2, 3) = dr_dq * dmoved.leftCols<3>();
  if (jacobians[1]) Eigen::Map<RowMajor2>(jacobians[1], 2, 3) = dr_dq;
  if (jacobians[2]) Eigen::Map<RowMajor2>(jacobians[2], 2, identity_.cols()) = dr_dx * identity_;
  if (jacobians[3]) Eigen::Map<RowMajor2>(jacobians[3], 2, expression_.cols()) = dr_dx * expression_;
  if (jacobians[4]) {
    // The zoom scales the focal lengths and dollies the camera along its axis.
    jacobians[4][0] = weight_ * camera_.fx * u + dr_dp(0, 2) * camera_.translation.z();
    jacobians[4][1] = weight_ * camera_.fy * v + dr_dp(1, 2) * camera_.translation.z();
  }
  return true;
}

}  // namespace headforge
