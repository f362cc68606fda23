// CPU kernels of ProjectGaussians: forward and analytic backward. The
// per-Gaussian algebra runs in double whatever the tensors' type, which keeps
// nearly singular and very large covariances finite.
#include <ATen/Parallel.h>
#include <Eigen/Core>

#include <algorithm>
#include <cmath>

#include "avatar/splat/splat_kernels.h"
#include "avatar/splat/splat_quat.h"

namespace headforge::splat::cpu {
namespace {

using Eigen::Matrix2d;
using Eigen::Matrix3d;
using Eigen::Vector3d;
using Eigen::Vector4d;
using Mat23 = Eigen::Matrix<double, 2, 3>;

constexpr int64_t kGrain = 2048;

// Everything the forward computes for one Gaussian, kept for the backward.
struct Projected {
  bool visible = false;
  Vector4d q_unit;
  double q_norm = 0;
  Matrix3d rotation;  // of the Gaussian
  Vector3d scales;
  Matrix3d cov_cam;  // camera-frame 3D covariance
  Vector3d p_cam;
  double tx = 0, ty = 0;
  bool clamped_x = false, clamped_y = false;
  Mat23 jacobian;
  Matrix2d cov2d;  // with the low-pass term
  Matrix2d conic;
  double u = 0, v = 0;
  int radius = 0;
};

template <typename T>
Projected ProjectOne(const T* mean, const T* quat, const T* log_scale, const ProjectParams& p,
                     const Matrix3d& cam_r, const Vector3d& cam_t) {
  Projected out;
  const Vector4d q(quat[0], quat[1], quat[2], quat[3]);
  out.q_norm = q.norm();
  if (!(out.q_norm > 0) || !std::isfinite(out.q_norm)) return out;
  out.q_unit = q / out.q_norm;
  RotationFromUnitQuat(out.q_unit, out.rotation);
  out.scales = Vector3d(std::exp(double(log_scale[0])), std::exp(double(log_scale[1])),
                        std::exp(double(log_scale[2])));
  out.p_cam = cam_r * Vector3d(mean[0], mean[1], mean[2]) + cam_t;
  const double z = out.p_cam.z();
  if (!(z >= p.near_plane && z <= p.far_plane)) return out;

  const Matrix3d m = out.rotation * out.scales.asDiagonal();
  out.cov_cam = cam_r * (m * m.transpose()) * cam_r.transpose();
  const double rx = out.p_cam.x() / z, ry = out.p_cam.y() / z;
  const double crx = std::clamp(rx, -p.lim_x_neg, p.lim_x_pos);
  const double cry = std::clamp(ry, -p.lim_y_neg, p.lim_y_pos);
  out.clamped_x = crx != rx;
  out.clamped_y = cry != ry;
  out.tx = z * crx;
  out.ty = z * cry;
  out.jacobian << p.fx / z, 0, -p.fx * out.tx / (z * z), 0, p.fy / z, -p.fy * out.ty / (z * z);
  out.cov2d = out.jacobian * out.cov_cam * out.jacobian.transpose();
  out.cov2d(0, 0) += p.eps2d;
  out.cov2d(1, 1) += p.eps2d;
  const double det = out.cov2d(0, 0) * out.cov2d(1, 1) - out.cov2d(0, 1) * out.cov2d(1, 0);
  if (!(det > 0) || !std::isfinite(det)) return out;
  out.conic << out.cov2d(1, 1) / det, -out.cov2d(0, 1) / det, -out.cov2d(1, 0) / det,
      out.cov2d(0, 0) / det;
  const double mid = 0.5 * (out.cov2d(0, 0) + out.cov2d(1, 1));
  const double lambda = mid + std::sqrt(std::max(0.1, mid * mid - det));
  const double radius = std::ceil(3.0 * std::sqrt(lambda));
  out.u = p.fx * rx + p.cx;
  out.v = p.fy * ry + p.cy;
  if (!std::isfinite(radius) || !std::isfinite(out.u) || !std::isfinite(out.v)) return out;
  if (out.u + radius < 0 || out.u - radius > p.width - 1 || out.v + radius < 0 ||
      out.v - radius > p.height - 1) {
    return out;
  }
  // Larger radii only mean "the whole image"; keep them inside int32.
  out.radius = static_cast<int>(std::min(radius, 1e8));
  out.visible = true;
  return out;
}

}  // namespace

void ProjectForward(const torch::Tensor& means, const torch::Tensor& quats,
                    const torch::Tensor& log_scales, const ProjectParams& params,
                    torch::Tensor& means2d, torch::Tensor& conics, torch::Tensor& depths,
                    torch::Tensor& radii) {
  const Matrix3d cam_r =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(params.rotation);
  const Vector3d cam_t(params.translation[0], params.translation[1], params.translation[2]);
  const int64_t n = means.size(0);
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "ProjectForward", [&] {
    const scalar_t* m = means.data_ptr<scalar_t>();
    const scalar_t* q = quats.data_ptr<scalar_t>();
    const scalar_t* s = log_scales.data_ptr<scalar_t>();
    scalar_t* out_m = means2d.data_ptr<scalar_t>();
    scalar_t* out_c = conics.data_ptr<scalar_t>();
    scalar_t* out_d = depths.data_ptr<scalar_t>();
    int32_t* out_r = radii.data_ptr<int32_t>();
    at::parallel_for(0, n, kGrain, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) {
        const Projected g = ProjectOne(m + 3 * i, q + 4 * i, s + 3 * i, params, cam_r, cam_t);
        if (!g.visible) {
          out_m[2 * i] = out_m[2 * i + 1] = 0;
          out_c[3 * i] = out_c[3 * i + 1] = out_c[3 * i + 2] = 0;
          out_d[i] = 0;
          out_r[i] = 0;
          continue;
        }
        out_m[2 * i] = static_cast<scalar_t>(g.u);
        out_m[2 * i + 1] = static_cast<scalar_t>(g.v);
        out_c[3 * i] = static_cast<scalar_t>(g.conic(0, 0));
        out_c[3 * i + 1] = static_cast<scalar_t>(g.conic(0, 1));
        out_c[3 * i + 2] = static_cast<scalar_t>(g.conic(1, 1));
        out_d[i] = static_cast<scalar_t>(g.p_cam.z());
        out_r[i] = g.radius;
      }
    });
  });
}

void ProjectBackward(const torch::Tensor& means, const torch::Tensor& quats,
                     const torch::Tensor& log_scales, const torch::Tensor& radii,
                     const ProjectParams& params, const torch::Tensor& v_means2d,
                     const torch::Tensor& v_conics, const torch::Tensor& v_depths,
                     torch::Tensor& v_means, torch::Tensor& v_quats, torch::Tensor& v_log_scales) {
  const Matrix3d cam_r =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(params.rotation);
  const Vector3d cam_t(params.translation[0], params.translation[1], params.translation[2]);
  const int64_t n = means.size(0);
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "ProjectBackward", [&] {
    const scalar_t* m = means.data_ptr<scalar_t>();
    const scalar_t* q = quats.data_ptr<scalar_t>();
    const scalar_t* s = log_scales.data_ptr<scalar_t>();
    const int32_t* r = radii.data_ptr<int32_t>();
    const scalar_t* gm = v_means2d.data_ptr<scalar_t>();
    const scalar_t* gc = v_conics.data_ptr<scalar_t>();
    const scalar_t* gd = v_depths.data_ptr<scalar_t>();
    scalar_t* out_m = v_means.data_ptr<scalar_t>();
    scalar_t* out_q = v_quats.data_ptr<scalar_t>();
    scalar_t* out_s = v_log_scales.data_ptr<scalar_t>();
    at::parallel_for(0, n, kGrain, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) {
        std::fill_n(out_m + 3 * i, 3, scalar_t(0));
        std::fill_n(out_q + 4 * i, 4, scalar_t(0));
        std::fill_n(out_s + 3 * i, 3, scalar_t(0));
        if (r[i] == 0) continue;
        const Projected g = ProjectOne(m + 3 * i, q + 4 * i, s + 3 * i, params, cam_r, cam_t);
        if (!g.visible) continue;
        const double z = g.p_cam.z(), x = g.p_cam.x(), y = g.p_cam.y();

        // Pixel position u = fx x / z + cx, v = fy y / z + cy; depth = z.
        Vector3d v_p(
            params.fx / z * gm[2 * i], params.fy / z * gm[2 * i + 1],
            -params.fx * x / (z * z) * gm[2 * i] - params.fy * y / (z * z) * gm[2 * i + 1] + gd[i]);

        // Conic = inverse(cov2d): d cov2d = -conic * G * conic, G symmetric
        // with the off-diagonal gradient split over its two entries.
        Matrix2d g_conic;
        g_conic << gc[3 * i], 0.5 * gc[3 * i + 1], 0.5 * gc[3 * i + 1], gc[3 * i + 2];
        const Matrix2d v_cov2d = -g.conic * g_conic * g.conic;

        // cov2d = J cov_cam J^T + eps I.
        const Matrix3d v_cov_cam = g.jacobian.transpose() * v_cov2d * g.jacobian;
        const Mat23 v_j = 2.0 * v_cov2d * g.jacobian * g.cov_cam;

        // J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]], tx = z clamp(x/z).
        const double dtx_dx = g.clamped_x ? 0.0 : 1.0;
        const double dtx_dz = g.clamped_x ? g.tx / z : 0.0;
        const double dty_dy = g.clamped_y ? 0.0 : 1.0;
        const double dty_dz = g.clamped_y ? g.ty / z : 0.0;
        const double z2 = z * z, z3 = z2 * z;
        v_p.x() += v_j(0, 2) * (-params.fx * dtx_dx / z2);
        v_p.y() += v_j(1, 2) * (-params.fy * dty_dy / z2);
        v_p.z() += v_j(0, 0) * (-params.fx / z2) + v_j(1, 1) * (-params.fy / z2) +
                   v_j(0, 2) * (-params.fx * (dtx_dz / z2 - 2 * g.tx / z3)) +
                   v_j(1, 2) * (-params.fy * (dty_dz / z2 - 2 * g.ty / z3));

        // p = W mean + t; cov_cam = W Sigma W^T.
        const Vector3d v_mean = cam_r.transpose() * v_p;
        const Matrix3d v_sigma = cam_r.transpose() * v_cov_cam * cam_r;
        // Sigma = M M^T with M = R diag(s).
        const Matrix3d mm = g.rotation * g.scales.asDiagonal();
        const Matrix3d v_m = (v_sigma + v_sigma.transpose()) * mm;
        const Matrix3d v_r = v_m * g.scales.asDiagonal();
        const Vector3d v_s = (v_m.cwiseProduct(g.rotation)).colwise().sum().transpose();
        Vector4d v_qu;
        UnitQuatGradient(g.q_unit, v_r, v_qu);
        const Vector4d v_q = (v_qu - g.q_unit * g.q_unit.dot(v_qu)) / g.q_norm;

        for (int k = 0; k < 3; ++k) {
          out_m[3 * i + k] = static_cast<scalar_t>(v_mean[k]);
          out_s[3 * i + k] = static_cast<scalar_t>(v_s[k] * g.scales[k]);
        }
        for (int k = 0; k < 4; ++k) out_q[4 * i + k] = static_cast<scalar_t>(v_q[k]);
      }
    });
  });
}

}  // namespace headforge::splat::cpu
