// Ceres cost functions of 3DMM tracking, each a templated functor with a
// static Create(). Parameter blocks, in order, are named in each comment.
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>

#include "reconstruction/landmark_basis.h"

namespace headforge {

// A pinhole camera looking at the head frame: pixel = K (R X + t).
struct TrackingCamera {
  double fx = 500, fy = 500, cx = 0, cy = 0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // cam_from_head
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  // The camera's centre in the head frame.
  Eigen::Vector3d Centre() const { return -rotation.transpose() * translation; }
  // Pixel of a head-frame point.
  Eigen::Vector2d Pixel(const Eigen::Vector3d& head_point) const {
    const Eigen::Vector3d p = rotation * head_point + translation;
    return {fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy};
  }
  // The same camera zoomed and dollied by `scale`: focal lengths and the
  // distance along its axis (translation z) multiplied by it.
  TrackingCamera WithFocalScale(double scale) const {
    TrackingCamera c = *this;
    c.fx *= scale;
    c.fy *= scale;
    c.translation.z() *= scale;
    return c;
  }
};

// One detected landmark against the model's landmark i, moved by the head's
// motion (angle-axis rotation and translation applied in the head frame) and
// seen by a fixed camera. `focal_scale` (1 unless the focal length is refined)
// zooms and dollies together: the focal lengths are multiplied by it and the
// camera's distance along its axis (translation z) too, so the head keeps its
// size in the image and only the perspective changes; otherwise a focal step
// would need every frame's depth to follow it. Residuals: 2, pixels times
// `weight`.
// Parameters: rotation[3], translation[3], identity[K], expression[E],
// focal_scale[1].
// The Jacobian is written out (tracking_costs.cc): the landmark is linear in
// the K + E coefficients, so it costs one 2x3 product per basis column;
// automatic differentiation would evaluate the whole basis sum again for
// every few of the ~80 derivatives, and this cost is most of calibrate's and
// track's time. tracking_costs_test checks it against finite differences.
class LandmarkReprojectionCost : public ceres::CostFunction {
 public:
  LandmarkReprojectionCost(const LandmarkBasis& basis, int landmark, const TrackingCamera& camera,
                           const Eigen::Vector2d& pixel, double weight);

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

  static ceres::CostFunction* Create(const LandmarkBasis& basis, int landmark, const TrackingCamera& camera,
                                     const Eigen::Vector2d& pixel, double weight) {
    return new LandmarkReprojectionCost(basis, landmark, camera, pixel, weight);
  }

 private:
  Eigen::Vector3d base_;
  Eigen::Matrix<double, 3, Eigen::Dynamic> identity_, expression_;
  TrackingCamera camera_;
  Eigen::Vector2d pixel_;
  double weight_;
};

// Temporal smoothness of consecutive coefficient vectors (expressions):
// weight * (b - a). Parameters: a[n], b[n]. Residuals: n.
struct CoefficientSmoothnessCost {
  explicit CoefficientSmoothnessCost(double weight) : weight_(weight) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residual) const {
    for (int i = 0; i < size_; ++i) residual[i] = T(weight_) * (parameters[1][i] - parameters[0][i]);
    return true;
  }

  static ceres::CostFunction* Create(int size, double weight) {
    auto* functor = new CoefficientSmoothnessCost(weight);
    functor->size_ = size;
    auto* cost = new ceres::DynamicAutoDiffCostFunction<CoefficientSmoothnessCost, 8>(functor);
    cost->AddParameterBlock(size);
    cost->AddParameterBlock(size);
    cost->SetNumResiduals(size);
    return cost;
  }

 private:
  double weight_;
  int size_ = 0;
};

// A prior pulling coefficients toward zero: weight * x. With a squared loss
// this is a Gaussian prior (identity, x ~ N(0, 1/weight^2)); under
// ceres::SoftLOneLoss it becomes a sparsity prior (expressions).
// Parameters: x[n]. Residuals: n.
struct CoefficientPriorCost {
  explicit CoefficientPriorCost(double weight) : weight_(weight) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residual) const {
    for (int i = 0; i < size_; ++i) residual[i] = T(weight_) * parameters[0][i];
    return true;
  }

  static ceres::CostFunction* Create(int size, double weight) {
    auto* functor = new CoefficientPriorCost(weight);
    functor->size_ = size;
    auto* cost = new ceres::DynamicAutoDiffCostFunction<CoefficientPriorCost, 8>(functor);
    cost->AddParameterBlock(size);
    cost->SetNumResiduals(size);
    return cost;
  }

 private:
  double weight_;
  int size_ = 0;
};

}  // namespace headforge
