// CUDA kernels of the splatting stages: the same arithmetic as the CPU
// kernels (splat_project_cpu.cc, splat_rasterize_*_cpu.cc), one thread per
// Gaussian for the projection and one 16x16 block per screen tile for the
// compositing. The backward writes one gradient row per tile-list entry and
// sums the rows of each Gaussian in a fixed order afterwards: no atomics, so
// gradients have the same bits on every run, as on the CPU.
#include "avatar/splat/splat_cuda_kernels.h"
#include "avatar/splat/splat_quat.h"

#include <cmath>
#include <type_traits>

namespace headforge::splat::cuda_kernels {
namespace {

constexpr int kTile = kSplatTileSize;
constexpr int kThreads = kTile * kTile;
constexpr int kWarps = kThreads / 32;
constexpr int kProjectThreads = 256;

// ---------------------------------------------------------------------------
// Projection, in double whatever the tensors' type (as on the CPU).

// 3x3 matrices, row-major.
struct M3 {
  double m[9];
  __device__ double& operator()(int i, int j) { return m[3 * i + j]; }
  __device__ double operator()(int i, int j) const { return m[3 * i + j]; }
};

__device__ M3 Mul(const M3& a, const M3& b) {
  M3 c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      c(i, j) = a(i, 0) * b(0, j) + a(i, 1) * b(1, j) + a(i, 2) * b(2, j);
    }
  }
  return c;
}

__device__ M3 Transposed(const M3& a) {
  M3 t;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) t(i, j) = a(j, i);
  }
  return t;
}

// What the forward computes for one Gaussian, kept for the backward.
struct Projected {
  bool visible = false;
  double q_unit[4];
  double q_norm = 0;
  M3 rotation;  // of the Gaussian
  double scales[3];
  M3 cov_cam;  // camera-frame 3D covariance
  double p_cam[3];
  double tx = 0, ty = 0;
  bool clamped_x = false, clamped_y = false;
  double jac[6];    // 2x3, row-major
  double cov2d[3];  // (xx, xy, yy) with the low-pass term
  double conic[3];  // (a, b, c)
  double u = 0, v = 0;
  int radius = 0;
};

template <typename T>
__device__ Projected ProjectOne(const T* mean, const T* quat, const T* log_scale,
                                const ProjectParams& p) {
  Projected out;
  const double q[4] = {double(quat[0]), double(quat[1]), double(quat[2]), double(quat[3])};
  out.q_norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(out.q_norm > 0) || !isfinite(out.q_norm)) return out;
  for (int k = 0; k < 4; ++k) out.q_unit[k] = q[k] / out.q_norm;
  RotationFromUnitQuat(out.q_unit, out.rotation);
  for (int k = 0; k < 3; ++k) out.scales[k] = exp(double(log_scale[k]));
  for (int i = 0; i < 3; ++i) {
    out.p_cam[i] = p.rotation[3 * i] * double(mean[0]) + p.rotation[3 * i + 1] * double(mean[1]) +
                   p.rotation[3 * i + 2] * double(mean[2]) + p.translation[i];
  }
  const double z = out.p_cam[2];
  if (!(z >= p.near_plane && z <= p.far_plane)) return out;

  M3 m;  // R diag(s)
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m(i, j) = out.rotation(i, j) * out.scales[j];
  }
  M3 cam_r;
  for (int k = 0; k < 9; ++k) cam_r.m[k] = p.rotation[k];
  out.cov_cam = Mul(Mul(cam_r, Mul(m, Transposed(m))), Transposed(cam_r));
  const double rx = out.p_cam[0] / z, ry = out.p_cam[1] / z;
  const double crx = fmin(fmax(rx, -p.lim_x_neg), p.lim_x_pos);
  const double cry = fmin(fmax(ry, -p.lim_y_neg), p.lim_y_pos);
  out.clamped_x = crx != rx;
  out.clamped_y = cry != ry;
  out.tx = z * crx;
  out.ty = z * cry;
  const double* j = out.jac;
  out.jac[0] = p.fx / z;
  out.jac[1] = 0;
  out.jac[2] = -p.fx * out.tx / (z * z);
  out.jac[3] = 0;
  out.jac[4] = p.fy / z;
  out.jac[5] = -p.fy * out.ty / (z * z);
  // cov2d = J cov_cam J^T + eps I.
  double jc[6];
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) {
      jc[3 * r + c] = j[3 * r] * out.cov_cam(0, c) + j[3 * r + 1] * out.cov_cam(1, c) +
                      j[3 * r + 2] * out.cov_cam(2, c);
    }
  }
  auto jcjt = [&](int r, int s) {
    return jc[3 * r] * j[3 * s] + jc[3 * r + 1] * j[3 * s + 1] + jc[3 * r + 2] * j[3 * s + 2];
  };
  out.cov2d[0] = jcjt(0, 0) + p.eps2d;
  out.cov2d[1] = jcjt(0, 1);
  const double cov_yx = jcjt(1, 0);
  out.cov2d[2] = jcjt(1, 1) + p.eps2d;
  const double det = out.cov2d[0] * out.cov2d[2] - out.cov2d[1] * cov_yx;
  if (!(det > 0) || !isfinite(det)) return out;
  out.conic[0] = out.cov2d[2] / det;
  out.conic[1] = -out.cov2d[1] / det;
  out.conic[2] = out.cov2d[0] / det;
  const double mid = 0.5 * (out.cov2d[0] + out.cov2d[2]);
  const double lambda = mid + sqrt(fmax(0.1, mid * mid - det));
  const double radius = ceil(3.0 * sqrt(lambda));
  out.u = p.fx * rx + p.cx;
  out.v = p.fy * ry + p.cy;
  if (!isfinite(radius) || !isfinite(out.u) || !isfinite(out.v)) return out;
  if (out.u + radius < 0 || out.u - radius > p.width - 1 || out.v + radius < 0 ||
      out.v - radius > p.height - 1) {
    return out;
  }
  out.radius = static_cast<int>(fmin(radius, 1e8));
  out.visible = true;
  return out;
}

template <typename T>
__global__ void ProjectForwardKernel(const T* __restrict__ means, const T* __restrict__ quats,
                                     const T* __restrict__ log_scales, int64_t n,
                                     ProjectParams params, T* means2d, T* conics, T* depths,
                                     int32_t* radii) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Projected g = ProjectOne(means + 3 * i, quats + 4 * i, log_scales + 3 * i, params);
  if (!g.visible) {
    means2d[2 * i] = means2d[2 * i + 1] = T(0);
    conics[3 * i] = conics[3 * i + 1] = conics[3 * i + 2] = T(0);
    depths[i] = T(0);
    radii[i] = 0;
    return;
  }
  means2d[2 * i] = T(g.u);
  means2d[2 * i + 1] = T(g.v);
  conics[3 * i] = T(g.conic[0]);
  conics[3 * i + 1] = T(g.conic[1]);
  conics[3 * i + 2] = T(g.conic[2]);
  depths[i] = T(g.p_cam[2]);
  radii[i] = g.radius;
}

template <typename T>
__global__ void ProjectBackwardKernel(const T* __restrict__ means, const T* __restrict__ quats,
                                      const T* __restrict__ log_scales,
                                      const int32_t* __restrict__ radii, int64_t n,
                                      ProjectParams params, const T* __restrict__ gm,
                                      const T* __restrict__ gc, const T* __restrict__ gd, T* out_m,
                                      T* out_q, T* out_s) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  for (int k = 0; k < 3; ++k) out_m[3 * i + k] = out_s[3 * i + k] = T(0);
  for (int k = 0; k < 4; ++k) out_q[4 * i + k] = T(0);
  if (radii[i] == 0) return;
  const ProjectParams& p = params;
  const Projected g = ProjectOne(means + 3 * i, quats + 4 * i, log_scales + 3 * i, p);
  if (!g.visible) return;
  const double x = g.p_cam[0], y = g.p_cam[1], z = g.p_cam[2];
  const double gu = double(gm[2 * i]), gv = double(gm[2 * i + 1]);

  // Pixel position u = fx x / z + cx, v = fy y / z + cy; depth = z.
  double v_p[3] = {p.fx / z * gu, p.fy / z * gv,
                   -p.fx * x / (z * z) * gu - p.fy * y / (z * z) * gv + double(gd[i])};

  // Conic = inverse(cov2d): d cov2d = -conic G conic, G symmetric with the
  // off-diagonal gradient split over its two entries.
  const double ca = g.conic[0], cb = g.conic[1], cc = g.conic[2];
  const double g00 = double(gc[3 * i]), g01 = 0.5 * double(gc[3 * i + 1]),
               g11 = double(gc[3 * i + 2]);
  // conic * G
  const double t00 = ca * g00 + cb * g01, t01 = ca * g01 + cb * g11;
  const double t10 = cb * g00 + cc * g01, t11 = cb * g01 + cc * g11;
  // -(conic G) conic
  const double vc[4] = {-(t00 * ca + t01 * cb), -(t00 * cb + t01 * cc), -(t10 * ca + t11 * cb),
                        -(t10 * cb + t11 * cc)};  // row-major 2x2

  // cov2d = J cov_cam J^T + eps I:
  //   v_cov_cam = J^T v_cov2d J, v_J = 2 v_cov2d J cov_cam.
  const double* j = g.jac;
  double vj_tmp[6];  // v_cov2d J (2x3)
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) vj_tmp[3 * r + c] = vc[2 * r] * j[c] + vc[2 * r + 1] * j[3 + c];
  }
  M3 v_cov_cam;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) v_cov_cam(r, c) = j[r] * vj_tmp[c] + j[3 + r] * vj_tmp[3 + c];
  }
  double v_j[6];
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) {
      v_j[3 * r + c] =
          2.0 * (vj_tmp[3 * r] * g.cov_cam(0, c) + vj_tmp[3 * r + 1] * g.cov_cam(1, c) +
                 vj_tmp[3 * r + 2] * g.cov_cam(2, c));
    }
  }

  // J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]], tx = z clamp(x/z).
  const double dtx_dx = g.clamped_x ? 0.0 : 1.0;
  const double dtx_dz = g.clamped_x ? g.tx / z : 0.0;
  const double dty_dy = g.clamped_y ? 0.0 : 1.0;
  const double dty_dz = g.clamped_y ? g.ty / z : 0.0;
  const double z2 = z * z, z3 = z2 * z;
  v_p[0] += v_j[2] * (-p.fx * dtx_dx / z2);
  v_p[1] += v_j[5] * (-p.fy * dty_dy / z2);
  v_p[2] += v_j[0] * (-p.fx / z2) + v_j[4] * (-p.fy / z2) +
            v_j[2] * (-p.fx * (dtx_dz / z2 - 2 * g.tx / z3)) +
            v_j[5] * (-p.fy * (dty_dz / z2 - 2 * g.ty / z3));

  // p = W mean + t; cov_cam = W Sigma W^T.
  M3 cam_r;
  for (int k = 0; k < 9; ++k) cam_r.m[k] = p.rotation[k];
  double v_mean[3];
  for (int k = 0; k < 3; ++k) {
    v_mean[k] = cam_r(0, k) * v_p[0] + cam_r(1, k) * v_p[1] + cam_r(2, k) * v_p[2];
  }
  const M3 v_sigma = Mul(Mul(Transposed(cam_r), v_cov_cam), cam_r);
  // Sigma = M M^T with M = R diag(s).
  M3 mm, v_sym;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      mm(r, c) = g.rotation(r, c) * g.scales[c];
      v_sym(r, c) = v_sigma(r, c) + v_sigma(c, r);
    }
  }
  const M3 v_m = Mul(v_sym, mm);
  M3 v_r;
  double v_s[3] = {0, 0, 0};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      v_r(r, c) = v_m(r, c) * g.scales[c];
      v_s[c] += v_m(r, c) * g.rotation(r, c);
    }
  }
  double v_qu[4];
  UnitQuatGradient(g.q_unit, v_r, v_qu);
  const double dot =
      g.q_unit[0] * v_qu[0] + g.q_unit[1] * v_qu[1] + g.q_unit[2] * v_qu[2] + g.q_unit[3] * v_qu[3];
  for (int k = 0; k < 3; ++k) {
    out_m[3 * i + k] = T(v_mean[k]);
    out_s[3 * i + k] = T(v_s[k] * g.scales[k]);
  }
  for (int k = 0; k < 4; ++k) out_q[4 * i + k] = T((v_qu[k] - g.q_unit[k] * dot) / g.q_norm);
}

// ---------------------------------------------------------------------------
// Tile lists.

struct TileRange {
  int x0, x1, y0, y1;  // inclusive; empty when x0 > x1
};

template <typename T>
__device__ TileRange RangeOf(const T* mean2d, int radius, int tiles_x, int tiles_y) {
  if (radius <= 0) return {1, 0, 1, 0};
  const double r = radius;
  const int x0 = static_cast<int>(floor((double(mean2d[0]) - r) / kTile));
  const int x1 = static_cast<int>(floor((double(mean2d[0]) + r) / kTile));
  const int y0 = static_cast<int>(floor((double(mean2d[1]) - r) / kTile));
  const int y1 = static_cast<int>(floor((double(mean2d[1]) + r) / kTile));
  return {max(x0, 0), min(x1, tiles_x - 1), max(y0, 0), min(y1, tiles_y - 1)};
}

template <typename T>
__global__ void CountTilesKernel(const T* __restrict__ means2d, const int32_t* __restrict__ radii,
                                 int64_t n, int tiles_x, int tiles_y, int64_t* counts) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const TileRange t = RangeOf(means2d + 2 * i, radii[i], tiles_x, tiles_y);
  counts[i] = t.x0 > t.x1 || t.y0 > t.y1 ? 0 : int64_t(t.x1 - t.x0 + 1) * (t.y1 - t.y0 + 1);
}

template <typename T>
__global__ void EmitTileEntriesKernel(const T* __restrict__ means2d,
                                      const int32_t* __restrict__ radii,
                                      const int64_t* __restrict__ order,
                                      const int64_t* __restrict__ offsets, int64_t n, int tiles_x,
                                      int tiles_y, int32_t* tile_keys, int32_t* gaussian_ids) {
  const int64_t p = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p >= n) return;
  const int64_t g = order[p];
  const TileRange t = RangeOf(means2d + 2 * g, radii[g], tiles_x, tiles_y);
  int64_t k = offsets[p];
  for (int y = t.y0; y <= t.y1; ++y) {
    for (int x = t.x0; x <= t.x1; ++x) {
      tile_keys[k] = y * tiles_x + x;
      gaussian_ids[k] = static_cast<int32_t>(g);
      ++k;
    }
  }
}

// ---------------------------------------------------------------------------
// Compositing. One block per tile, one thread per pixel. The channels are
// done kChannels at a time (K below): a pass per group, each redoing the
// per-pixel alphas, so that any C fits in registers.

__device__ inline float Exp(float x) { return expf(x); }
__device__ inline double Exp(double x) { return exp(x); }

// Copies `count` list entries' Gaussians into shared memory, the block's
// threads together: geometry (mean x, y relative to the tile's corner at
// (x0, y0); conic a, b, c; opacity) and channels [ch0, ch0 + K), zero past C.
template <typename T, int K>
__device__ void LoadEntries(const int32_t* __restrict__ entry_ids, int count,
                            const T* __restrict__ means2d, const T* __restrict__ conics,
                            const T* __restrict__ opacities, const T* __restrict__ features,
                            int channels, int ch0, int x0, int y0, T (*geo)[6], T (*feat)[K]) {
  for (int i = threadIdx.x; i < count; i += kThreads) {
    const int32_t g = entry_ids[i];
    geo[i][0] = means2d[2 * g] - T(x0);
    geo[i][1] = means2d[2 * g + 1] - T(y0);
    geo[i][2] = conics[3 * g];
    geo[i][3] = conics[3 * g + 1];
    geo[i][4] = conics[3 * g + 2];
    geo[i][5] = opacities[g];
  }
  const int kc = min(K, channels - ch0);
  for (int i = threadIdx.x; i < count * K; i += kThreads) {
    const int e = i / K, c = i % K;
    feat[e][c] = c < kc ? features[int64_t(entry_ids[e]) * channels + ch0 + c] : T(0);
  }
}

// Gaussians loaded into shared memory per step: about 1 KiB of geometry.
template <typename T>
__host__ __device__ constexpr int ForwardBatch() {
  return 1024 / sizeof(T);
}

template <typename T, int K>
__global__ void __launch_bounds__(kThreads)
    RasterizeForwardKernel(const T* __restrict__ means2d, const T* __restrict__ conics,
                           const T* __restrict__ features, const T* __restrict__ opacities,
                           const T* __restrict__ background, const int32_t* __restrict__ offsets,
                           const int32_t* __restrict__ ids, int channels, int ch0, int tiles_x,
                           int width, int height, T* image, T* transmittance, int32_t* last) {
  constexpr int B = ForwardBatch<T>();
  __shared__ T s_geo[B][6];  // mean x, y relative to the tile; conic a, b, c; opacity
  __shared__ T s_feat[B][K];
  const int tile = blockIdx.x;
  const int x0 = (tile % tiles_x) * kTile, y0 = (tile / tiles_x) * kTile;
  const int tx = threadIdx.x % kTile, ty = threadIdx.x / kTile;
  const int px = x0 + tx, py = y0 + ty;
  const bool inside = px < width && py < height;
  const int kc = min(K, channels - ch0);
  const int32_t begin = offsets[tile], end = offsets[tile + 1];
  const T min_alpha = T(kMinAlpha), max_alpha = T(kMaxAlpha), min_trans = T(kMinTransmittance);

  T trans = T(1);
  int32_t count = 0;
  bool done = !inside;
  T acc[K];
  for (int c = 0; c < K; ++c) acc[c] = T(0);

  for (int32_t base = begin; base < end; base += B) {
    // Also the barrier before the shared arrays are overwritten.
    if (__syncthreads_count(!done) == 0) break;
    const int nb = min(B, end - base);
    LoadEntries<T, K>(ids + base, nb, means2d, conics, opacities, features, channels, ch0, x0, y0,
                      s_geo, s_feat);
    __syncthreads();
    if (done) continue;
    for (int e = 0; e < nb; ++e) {
      const T dx = s_geo[e][0] - T(tx), dy = s_geo[e][1] - T(ty);
      const T a = s_geo[e][2], b = s_geo[e][3], c = s_geo[e][4], o = s_geo[e][5];
      const T sigma = T(0.5) * (a * dx * dx + c * dy * dy) + (b * dy) * dx;
      const T alpha = min(o * Exp(-sigma), max_alpha);
      if (!(sigma >= T(0)) || !(alpha >= min_alpha)) continue;
      const T t_next = trans * (T(1) - alpha);
      if (t_next < min_trans) {
        done = true;
        break;
      }
      const T w = alpha * trans;
      for (int ch = 0; ch < K; ++ch) acc[ch] += w * s_feat[e][ch];
      trans = t_next;
      count = base + e - begin + 1;
    }
  }
  if (!inside) return;
  const int64_t plane = int64_t(width) * height;
  const int64_t pixel = int64_t(py) * width + px;
  if (ch0 == 0) {
    transmittance[pixel] = trans;
    last[pixel] = count;
  }
  for (int ch = 0; ch < kc; ++ch) {
    image[(ch0 + ch) * plane + pixel] = acc[ch] + trans * background[ch0 + ch];
  }
}

__device__ inline float WarpSum(float v) {
  for (int s = 16; s > 0; s >>= 1) v += __shfl_xor_sync(0xffffffffu, v, s);
  return v;
}
__device__ inline double WarpSum(double v) {
  for (int s = 16; s > 0; s >>= 1) v += __shfl_xor_sync(0xffffffffu, v, s);
  return v;
}

// Entries per step of the backward: its per-warp partial sums take
// B x 8 warps x (6 + K) values of shared memory, 38 KiB at K = 32.
template <typename T>
__host__ __device__ constexpr int BackwardBatch() {
  return 128 / sizeof(T);
}

template <typename T, int K>
__global__ void __launch_bounds__(kThreads)
    RasterizeBackwardKernel(const T* __restrict__ means2d, const T* __restrict__ conics,
                            const T* __restrict__ features, const T* __restrict__ opacities,
                            const T* __restrict__ background, const int32_t* __restrict__ offsets,
                            const int32_t* __restrict__ ids, int channels, int ch0, int tiles_x,
                            int width, int height, const T* __restrict__ transmittance,
                            const int32_t* __restrict__ last, const T* __restrict__ v_image,
                            const T* __restrict__ v_alpha, T* entry_grads) {
  constexpr int B = BackwardBatch<T>();
  constexpr int V = kGradFeatures + K;  // values per entry (GradientColumn), K features
  __shared__ T s_geo[B][6];
  __shared__ T s_feat[B][K];
  __shared__ T s_part[B][kWarps][V];
  __shared__ int32_t s_max_count;
  const int tile = blockIdx.x;
  const int x0 = (tile % tiles_x) * kTile, y0 = (tile / tiles_x) * kTile;
  const int tx = threadIdx.x % kTile, ty = threadIdx.x / kTile;
  const int px = x0 + tx, py = y0 + ty;
  const bool inside = px < width && py < height;
  const int kc = min(K, channels - ch0);
  const int warp = threadIdx.x / 32, lane = threadIdx.x % 32;
  const int stride = kGradFeatures + channels;
  const int32_t begin = offsets[tile];
  const T min_alpha = T(kMinAlpha), max_alpha = T(kMaxAlpha);
  const int64_t plane = int64_t(width) * height;
  const int64_t pixel = int64_t(py) * width + px;

  T trans = T(1);
  T v_alpha_final = T(0);  // d loss / d alpha output, times T_final (first pass only)
  int32_t count = 0;
  T v_pix[K], behind[K];
  for (int c = 0; c < K; ++c) v_pix[c] = behind[c] = T(0);
  if (inside) {
    trans = transmittance[pixel];
    count = last[pixel];
    if (ch0 == 0) v_alpha_final = v_alpha[pixel] * trans;
    for (int c = 0; c < kc; ++c) {
      v_pix[c] = v_image[(ch0 + c) * plane + pixel];
      behind[c] = trans * background[ch0 + c];
    }
  }
  if (threadIdx.x == 0) s_max_count = 0;
  __syncthreads();
  atomicMax(&s_max_count, count);
  __syncthreads();
  const int32_t max_count = s_max_count;

  for (int32_t hi = max_count; hi > 0; hi -= B) {
    const int32_t lo = max(0, hi - B);
    const int nb = hi - lo;
    __syncthreads();  // the previous step's shared arrays are read
    LoadEntries<T, K>(ids + begin + lo, nb, means2d, conics, opacities, features, channels, ch0,
                      x0, y0, s_geo, s_feat);
    __syncthreads();
    for (int e = nb - 1; e >= 0; --e) {
      const int32_t index = lo + e;
      const T dx = s_geo[e][0] - T(tx), dy = s_geo[e][1] - T(ty);
      const T a = s_geo[e][2], b = s_geo[e][3], c = s_geo[e][4], o = s_geo[e][5];
      const T sigma = T(0.5) * (a * dx * dx + c * dy * dy) + (b * dy) * dx;
      const T vis = Exp(-sigma);
      const T raw = o * vis;
      const T alpha = min(raw, max_alpha);
      const bool use = count > index && sigma >= T(0) && alpha >= min_alpha;
      T g[V];
      for (int v = 0; v < V; ++v) g[v] = T(0);
      if (use) {
        const T inv = T(1) / (T(1) - alpha);
        const T t_i = trans * inv;
        trans = t_i;
        const T w = alpha * t_i;
        // d colour_c / d alpha_i = f_c T_i - behind_c / (1 - alpha_i).
        T v_alpha_pix = v_alpha_final * inv;
        for (int ch = 0; ch < K; ++ch) {
          const T f = s_feat[e][ch];
          g[kGradFeatures + ch] = w * v_pix[ch];
          v_alpha_pix += v_pix[ch] * (f * t_i - behind[ch] * inv);
          behind[ch] += f * w;
        }
        // Only unclamped alphas pass a gradient to opacity and sigma.
        const T v_o = raw < max_alpha ? v_alpha_pix * vis : T(0);
        const T v_sigma = -o * v_o;
        g[kGradMx] = v_sigma * (a * dx + b * dy);
        g[kGradMy] = v_sigma * (b * dx + c * dy);
        g[kGradA] = v_sigma * (T(0.5) * dx * dx);
        g[kGradB] = v_sigma * (dx * dy);
        g[kGradC] = v_sigma * (T(0.5) * dy * dy);
        g[kGradO] = v_o;
      }
      if (__any_sync(0xffffffffu, use)) {
        for (int v = 0; v < V; ++v) g[v] = WarpSum(g[v]);
      }
      if (lane == 0) {
        for (int v = 0; v < V; ++v) s_part[e][warp][v] = g[v];
      }
    }
    __syncthreads();
    // The warps' partial sums, added in warp order: one row per entry.
    for (int i = threadIdx.x; i < nb * V; i += kThreads) {
      const int e = i / V, v = i % V;
      T sum = T(0);
      for (int w = 0; w < kWarps; ++w) sum += s_part[e][w][v];
      T* row = entry_grads + int64_t(begin + lo + e) * stride;
      if (v < kGradFeatures) {
        row[v] = ch0 == 0 ? sum : row[v] + sum;
      } else if (v - kGradFeatures < kc) {
        row[ch0 + v] = sum;
      }
    }
  }
}

template <typename T>
__global__ void SumEntriesKernel(const T* __restrict__ entry_grads,
                                 const int64_t* __restrict__ entries,
                                 const int64_t* __restrict__ starts, int64_t n, int stride,
                                 T* out) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n * stride) return;
  const int64_t g = i / stride;
  const int v = static_cast<int>(i % stride);
  T sum = T(0);
  for (int64_t j = starts[g]; j < starts[g + 1]; ++j) sum += entry_grads[entries[j] * stride + v];
  out[i] = sum;
}

unsigned Blocks(int64_t n, int threads) {
  return static_cast<unsigned>((n + threads - 1) / threads);
}

// Calls f(std::integral_constant<int, K>) with K the channels per pass: the
// smallest of 4, 8, 16 and 32 that holds them all, else 32 (several passes).
template <typename F>
void WithChannelGroup(int channels, F&& f) {
  if (channels <= 4) {
    f(std::integral_constant<int, 4>());
  } else if (channels <= 8) {
    f(std::integral_constant<int, 8>());
  } else if (channels <= 16) {
    f(std::integral_constant<int, 16>());
  } else {
    f(std::integral_constant<int, 32>());
  }
}

template <typename T, int K>
void LaunchForward(const T* means2d, const T* conics, const T* features, const T* opacities,
                   const T* background, const int32_t* offsets, const int32_t* ids, int channels,
                   int tiles_x, int tiles, int width, int height, T* image, T* transmittance,
                   int32_t* last, cudaStream_t stream) {
  for (int ch0 = 0; ch0 < channels; ch0 += K) {
    RasterizeForwardKernel<T, K><<<tiles, kThreads, 0, stream>>>(
        means2d, conics, features, opacities, background, offsets, ids, channels, ch0, tiles_x,
        width, height, image, transmittance, last);
  }
}

template <typename T, int K>
void LaunchBackward(const T* means2d, const T* conics, const T* features, const T* opacities,
                    const T* background, const int32_t* offsets, const int32_t* ids, int channels,
                    int tiles_x, int tiles, int width, int height, const T* transmittance,
                    const int32_t* last, const T* v_image, const T* v_alpha, T* entry_grads,
                    cudaStream_t stream) {
  for (int ch0 = 0; ch0 < channels; ch0 += K) {
    RasterizeBackwardKernel<T, K><<<tiles, kThreads, 0, stream>>>(
        means2d, conics, features, opacities, background, offsets, ids, channels, ch0, tiles_x,
        width, height, transmittance, last, v_image, v_alpha, entry_grads);
  }
}

}  // namespace

template <typename T>
cudaError_t ProjectForward(const T* means, const T* quats, const T* log_scales, int64_t n,
                           const ProjectParams& params, T* means2d, T* conics, T* depths,
                           int32_t* radii, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  ProjectForwardKernel<T><<<Blocks(n, kProjectThreads), kProjectThreads, 0, stream>>>(
      means, quats, log_scales, n, params, means2d, conics, depths, radii);
  return cudaGetLastError();
}

template <typename T>
cudaError_t ProjectBackward(const T* means, const T* quats, const T* log_scales,
                            const int32_t* radii, int64_t n, const ProjectParams& params,
                            const T* v_means2d, const T* v_conics, const T* v_depths, T* v_means,
                            T* v_quats, T* v_log_scales, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  ProjectBackwardKernel<T><<<Blocks(n, kProjectThreads), kProjectThreads, 0, stream>>>(
      means, quats, log_scales, radii, n, params, v_means2d, v_conics, v_depths, v_means, v_quats,
      v_log_scales);
  return cudaGetLastError();
}

template <typename T>
cudaError_t CountTiles(const T* means2d, const int32_t* radii, int64_t n, int tiles_x, int tiles_y,
                       int64_t* counts, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  CountTilesKernel<T><<<Blocks(n, kProjectThreads), kProjectThreads, 0, stream>>>(
      means2d, radii, n, tiles_x, tiles_y, counts);
  return cudaGetLastError();
}

template <typename T>
cudaError_t EmitTileEntries(const T* means2d, const int32_t* radii, const int64_t* order,
                            const int64_t* offsets, int64_t n, int tiles_x, int tiles_y,
                            int32_t* tile_keys, int32_t* gaussian_ids, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  EmitTileEntriesKernel<T><<<Blocks(n, kProjectThreads), kProjectThreads, 0, stream>>>(
      means2d, radii, order, offsets, n, tiles_x, tiles_y, tile_keys, gaussian_ids);
  return cudaGetLastError();
}

template <typename T>
cudaError_t RasterizeForward(const T* means2d, const T* conics, const T* features,
                             const T* opacities, const T* background, const int32_t* tile_offsets,
                             const int32_t* gaussian_ids, int channels, int width, int height,
                             T* image, T* transmittance, int32_t* last, cudaStream_t stream) {
  const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int tiles = tiles_x * tiles_y;
  WithChannelGroup(channels, [&](auto group) {
    LaunchForward<T, decltype(group)::value>(means2d, conics, features, opacities, background,
                                             tile_offsets, gaussian_ids, channels, tiles_x, tiles,
                                             width, height, image, transmittance, last, stream);
  });
  return cudaGetLastError();
}

template <typename T>
cudaError_t RasterizeBackward(const T* means2d, const T* conics, const T* features,
                              const T* opacities, const T* background, const int32_t* tile_offsets,
                              const int32_t* gaussian_ids, int channels, int width, int height,
                              const T* transmittance, const int32_t* last, const T* v_image,
                              const T* v_alpha, T* entry_grads, cudaStream_t stream) {
  const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int tiles = tiles_x * tiles_y;
  WithChannelGroup(channels, [&](auto group) {
    LaunchBackward<T, decltype(group)::value>(means2d, conics, features, opacities, background,
                                              tile_offsets, gaussian_ids, channels, tiles_x,
                                              tiles, width, height, transmittance, last, v_image,
                                              v_alpha, entry_grads, stream);
  });
  return cudaGetLastError();
}

template <typename T>
cudaError_t SumEntriesPerGaussian(const T* entry_grads, const int64_t* entries,
                                  const int64_t* starts, int64_t n, int stride, T* out,
                                  cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  SumEntriesKernel<T><<<Blocks(n * stride, kProjectThreads), kProjectThreads, 0, stream>>>(
      entry_grads, entries, starts, n, stride, out);
  return cudaGetLastError();
}

#define HEADFORGE_INSTANTIATE(T)                                                                   \
  template cudaError_t ProjectForward<T>(const T*, const T*, const T*, int64_t,                    \
                                         const ProjectParams&, T*, T*, T*, int32_t*,               \
                                         cudaStream_t);                                            \
  template cudaError_t ProjectBackward<T>(const T*, const T*, const T*, const int32_t*, int64_t,   \
                                          const ProjectParams&, const T*, const T*, const T*, T*,  \
                                          T*, T*, cudaStream_t);                                   \
  template cudaError_t CountTiles<T>(const T*, const int32_t*, int64_t, int, int, int64_t*,        \
                                     cudaStream_t);                                                \
  template cudaError_t EmitTileEntries<T>(const T*, const int32_t*, const int64_t*,                \
                                          const int64_t*, int64_t, int, int, int32_t*, int32_t*,   \
                                          cudaStream_t);                                           \
  template cudaError_t RasterizeForward<T>(const T*, const T*, const T*, const T*, const T*,       \
                                           const int32_t*, const int32_t*, int, int, int, T*, T*,  \
                                           int32_t*, cudaStream_t);                                \
  template cudaError_t RasterizeBackward<T>(                                                       \
      const T*, const T*, const T*, const T*, const T*, const int32_t*, const int32_t*, int, int,  \
      int, const T*, const int32_t*, const T*, const T*, T*, cudaStream_t);                        \
  template cudaError_t SumEntriesPerGaussian<T>(const T*, const int64_t*, const int64_t*, int64_t, \
                                                int, T*, cudaStream_t);

HEADFORGE_INSTANTIATE(float)
HEADFORGE_INSTANTIATE(double)
#undef HEADFORGE_INSTANTIATE

}  // namespace headforge::splat::cuda_kernels
