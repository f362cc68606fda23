// Ceres cost functions of the calibration layer.
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <cmath>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace headforge {

// Reprojection of a free 3D point through a fixed 3x4 projection matrix.
// Parameters: point[3]. Residuals: 2 pixels, scaled by `weight`.
struct PointReprojectionCost {
  PointReprojectionCost(const Eigen::Matrix<double, 3, 4>& projection, const Eigen::Vector2d& pixel, double weight)
      : projection_(projection), pixel_(pixel), weight_(weight) {}

  template <typename T>
  bool operator()(const T* point, T* residual) const {
    T p[3];
    for (int r = 0; r < 3; ++r)
      p[r] = T(projection_(r, 0)) * point[0] + T(projection_(r, 1)) * point[1] + T(projection_(r, 2)) * point[2] +
             T(projection_(r, 3));
    residual[0] = T(weight_) * (p[0] / p[2] - T(pixel_.x()));
    residual[1] = T(weight_) * (p[1] / p[2] - T(pixel_.y()));
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Matrix<double, 3, 4>& projection, const Eigen::Vector2d& pixel,
                                     double weight) {
    return new ceres::AutoDiffCostFunction<PointReprojectionCost, 2, 3>(
        new PointReprojectionCost(projection, pixel, weight));
  }

 private:
  Eigen::Matrix<double, 3, 4> projection_;
  Eigen::Vector2d pixel_;
  double weight_;
};

// A head-frame point carried into the world by a similarity and seen through
// a fixed 3x4 projection matrix: x_world = exp(log_scale) R(w) x_head + t.
// Parameters: world_from_head[7] = w[3] (angle-axis), t[3], log_scale.
// Residuals: 2 pixels, scaled by `weight`.
struct SimilarityReprojectionCost {
  SimilarityReprojectionCost(const Eigen::Vector3d& point, const Eigen::Matrix<double, 3, 4>& projection,
                             const Eigen::Vector2d& pixel, double weight)
      : point_(point), projection_(projection), pixel_(pixel), weight_(weight) {}

  template <typename T>
  bool operator()(const T* world_from_head, T* residual) const {
    const T x[3] = {T(point_.x()), T(point_.y()), T(point_.z())};
    T rotated[3];
    ceres::AngleAxisRotatePoint(world_from_head, x, rotated);
    const T s = exp(world_from_head[6]);
    T w[3];
    for (int i = 0; i < 3; ++i) w[i] = s * rotated[i] + world_from_head[3 + i];
    T p[3];
    for (int r = 0; r < 3; ++r)
      p[r] = T(projection_(r, 0)) * w[0] + T(projection_(r, 1)) * w[1] + T(projection_(r, 2)) * w[2] +
             T(projection_(r, 3));
    if (!(p[2] > T(0))) return false;  // behind the camera: Ceres rejects the step
    residual[0] = T(weight_) * (p[0] / p[2] - T(pixel_.x()));
    residual[1] = T(weight_) * (p[1] / p[2] - T(pixel_.y()));
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& point, const Eigen::Matrix<double, 3, 4>& projection,
                                     const Eigen::Vector2d& pixel, double weight) {
    return new ceres::AutoDiffCostFunction<SimilarityReprojectionCost, 2, 7>(
        new SimilarityReprojectionCost(point, projection, pixel, weight));
  }

 private:
  Eigen::Vector3d point_;
  Eigen::Matrix<double, 3, 4> projection_;
  Eigen::Vector2d pixel_;
  double weight_;
};

// A known 3D point (head frame) seen by a pinhole camera with focal f and a
// fixed principal point; the pose is an angle-axis rotation and a translation
// (cam_from_head). Parameters: focal[1], rotation[3], translation[3].
struct PosedReprojectionCost {
  PosedReprojectionCost(const Eigen::Vector3d& point, const Eigen::Vector2d& pixel, const Eigen::Vector2d& principal,
                        double weight)
      : point_(point), pixel_(pixel), principal_(principal), weight_(weight) {}

  template <typename T>
  bool operator()(const T* focal, const T* rotation, const T* translation, T* residual) const {
    const T x[3] = {T(point_.x()), T(point_.y()), T(point_.z())};
    T p[3];
    ceres::AngleAxisRotatePoint(rotation, x, p);
    for (int i = 0; i < 3; ++i) p[i] += translation[i];
    residual[0] = T(weight_) * (focal[0] * p[0] / p[2] + T(principal_.x()) - T(pixel_.x()));
    residual[1] = T(weight_) * (focal[0] * p[1] / p[2] + T(principal_.y()) - T(pixel_.y()));
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& point, const Eigen::Vector2d& pixel,
                                     const Eigen::Vector2d& principal, double weight) {
    return new ceres::AutoDiffCostFunction<PosedReprojectionCost, 2, 1, 3, 3>(
        new PosedReprojectionCost(point, pixel, principal, weight));
  }

 private:
  Eigen::Vector3d point_;
  Eigen::Vector2d pixel_, principal_;
  double weight_;
};

// Temporal smoothness of consecutive poses: weighted differences of their
// angle-axis rotations and translations. Parameters: r0[3], t0[3], r1[3], t1[3].
struct PoseSmoothnessCost {
  PoseSmoothnessCost(double rotation_weight, double translation_weight)
      : rotation_weight_(rotation_weight), translation_weight_(translation_weight) {}

  template <typename T>
  bool operator()(const T* r0, const T* t0, const T* r1, const T* t1, T* residual) const {
    for (int i = 0; i < 3; ++i) {
      residual[i] = T(rotation_weight_) * (r1[i] - r0[i]);
      residual[3 + i] = T(translation_weight_) * (t1[i] - t0[i]);
    }
    return true;
  }

  static ceres::CostFunction* Create(double rotation_weight, double translation_weight) {
    return new ceres::AutoDiffCostFunction<PoseSmoothnessCost, 6, 3, 3, 3, 3>(
        new PoseSmoothnessCost(rotation_weight, translation_weight));
  }

 private:
  double rotation_weight_, translation_weight_;
};

// A log-normal prior on a positive scale (a focal length, or a factor on
// one): weight * ln(x / centre). With weight = sigma_px / sigma_log it is the
// prior's share of a least-squares problem whose residuals are pixels of
// noise sigma_px. Parameter: x[1].
struct LogPriorCost {
  LogPriorCost(double centre, double weight) : centre_(centre), weight_(weight) {}

  template <typename T>
  bool operator()(const T* x, T* residual) const {
    residual[0] = T(weight_) * log(x[0] / T(centre_));
    return true;
  }

  static ceres::CostFunction* Create(double centre, double weight) {
    return new ceres::AutoDiffCostFunction<LogPriorCost, 1, 1>(new LogPriorCost(centre, weight));
  }

 private:
  double centre_, weight_;
};

// The standard deviation of ln(x) for a solved problem's parameter x (one
// value), from the inverse of J^T J at the solution, scaled by the residuals'
// variance (final cost over the degrees of freedom); 0 when the problem has
// no spare residuals or the covariance cannot be computed (a rank-deficient J).
inline double LogStandardDeviation(ceres::Problem* problem, double* x, double final_cost) {
  const int dof = problem->NumResiduals() - problem->NumParameters();
  if (dof <= 0 || !(*x > 0)) return 0;
  ceres::Covariance::Options options;
  options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(options);
  const std::vector<std::pair<const double*, const double*>> blocks = {{x, x}};
  if (!covariance.Compute(blocks, problem)) return 0;
  double variance = 0;
  if (!covariance.GetCovarianceBlock(x, x, &variance) || !(variance >= 0)) return 0;
  return std::sqrt(variance * 2 * final_cost / dof) / *x;
}

}  // namespace headforge
