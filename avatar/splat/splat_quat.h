// Quaternion algebra shared by the CPU and CUDA projection kernels, written
// once for any types with q[k] and m(i, j) (Eigen's on the CPU, plain arrays
// on the GPU). Internal to avatar/.
#pragma once

#if defined(__CUDACC__)
#define HEADFORGE_HOST_DEVICE __host__ __device__
#else
#define HEADFORGE_HOST_DEVICE
#endif

namespace headforge::splat {

// r = the rotation of the unit quaternion q = (w, x, y, z).
template <typename Q, typename R>
HEADFORGE_HOST_DEVICE void RotationFromUnitQuat(const Q& q, R& r) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  r(0, 0) = 1 - 2 * (y * y + z * z);
  r(0, 1) = 2 * (x * y - w * z);
  r(0, 2) = 2 * (x * z + w * y);
  r(1, 0) = 2 * (x * y + w * z);
  r(1, 1) = 1 - 2 * (x * x + z * z);
  r(1, 2) = 2 * (y * z - w * x);
  r(2, 0) = 2 * (x * z - w * y);
  r(2, 1) = 2 * (y * z + w * x);
  r(2, 2) = 1 - 2 * (x * x + y * y);
}

// d = d loss / d q from g = d loss / d R, for R = RotationFromUnitQuat(q).
template <typename Q, typename G, typename D>
HEADFORGE_HOST_DEVICE void UnitQuatGradient(const Q& q, const G& g, D& d) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  d[0] = 2 * (-z * g(0, 1) + y * g(0, 2) + z * g(1, 0) - x * g(1, 2) - y * g(2, 0) + x * g(2, 1));
  d[1] = 2 * (y * g(0, 1) + z * g(0, 2) + y * g(1, 0) - 2 * x * g(1, 1) - w * g(1, 2) +
              z * g(2, 0) + w * g(2, 1) - 2 * x * g(2, 2));
  d[2] = 2 * (-2 * y * g(0, 0) + x * g(0, 1) + w * g(0, 2) + x * g(1, 0) + z * g(1, 2) -
              w * g(2, 0) + z * g(2, 1) - 2 * y * g(2, 2));
  d[3] = 2 * (-2 * z * g(0, 0) - w * g(0, 1) + x * g(0, 2) + w * g(1, 0) - 2 * z * g(1, 1) +
              y * g(1, 2) + x * g(2, 0) + y * g(2, 1));
}

}  // namespace headforge::splat
