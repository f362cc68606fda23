// Pieces shared by the CPU rasterize kernels (forward and backward): a fast
// exponential the compiler can vectorise, the tile schedule and per-Gaussian
// row bounds. Internal to avatar/.
#pragma once

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "avatar/splat/splat_params.h"

namespace headforge::splat::cpu {

constexpr int kTile = kSplatTileSize;
constexpr int kTilePixels = kTile * kTile;

// One tile row as a GCC vector: 16 lanes of T, and the matching lane mask
// (comparisons give all-ones or zero lanes). The compiler maps these onto
// whatever vector unit the target has (one AVX-512 register, two AVX, four
// SSE), or plain code on other machines.
template <typename T> struct Lanes;
template <> struct Lanes<float> {
  typedef float Vec __attribute__((vector_size(kTile * sizeof(float))));
  typedef int32_t Mask __attribute__((vector_size(kTile * sizeof(int32_t))));
};
template <> struct Lanes<double> {
  typedef double Vec __attribute__((vector_size(kTile * sizeof(double))));
  typedef int64_t Mask __attribute__((vector_size(kTile * sizeof(int64_t))));
};

template <typename V, typename S>
inline V Splat(S s) {
  return V{} + s;
}

template <typename M, typename V>
inline V Select(M mask, V a, V b) {
  return mask ? a : b;
}

template <typename V>
inline V Min(V a, V b) {
  return a < b ? a : b;
}

template <typename M>
inline bool AnyLane(M m) {
  for (int j = 0; j < kTile; ++j) {
    if (m[j]) return true;
  }
  return false;
}

template <typename V>
inline auto SumLanes(V v) {
  auto s = v[0];
  for (int j = 1; j < kTile; ++j) s += v[j];
  return s;
}

// exp(x) lane by lane: in float a Cephes-style range reduction and degree-6
// polynomial (relative error below 2e-7), branch-free; arguments clamped to
// [-87, 88] where the result is a normal float. Double uses std::exp (the
// double kernels serve tests against the reference, not speed).
inline Lanes<float>::Vec Exp(Lanes<float>::Vec x) {
  using V = Lanes<float>::Vec;
  using M = Lanes<float>::Mask;
  x = x < -87.0f ? Splat<V>(-87.0f) : x;
  x = x > 88.0f ? Splat<V>(88.0f) : x;
  // Round to nearest by adding and removing 1.5 * 2^23.
  const V n = (x * 1.44269504088896341f + 12582912.0f) - 12582912.0f;
  V r = x - n * 0.693359375f;
  r = r + n * 2.12194440e-4f;
  V y = Splat<V>(1.9875691500e-4f);
  y = y * r + 1.3981999507e-3f;
  y = y * r + 8.3334519073e-3f;
  y = y * r + 4.1665795894e-2f;
  y = y * r + 1.6666665459e-1f;
  y = y * r + 5.0000001201e-1f;
  y = y * (r * r) + r + 1.0f;
  const M bits = (__builtin_convertvector(n, M) + 127) << 23;
  return y * (V)bits;  // a vector cast keeps the bits
}

inline Lanes<double>::Vec Exp(Lanes<double>::Vec x) {
  for (int j = 0; j < kTile; ++j) x[j] = std::exp(std::min(std::max(x[j], -700.0), 700.0));
  return x;
}

// 0, 1, ..., 15: the lanes' column offsets.
template <typename V>
inline V LaneIndex() {
  V v;
  for (int j = 0; j < kTile; ++j) v[j] = j;
  return v;
}

// Calls f(slot, tile) for every tile: slot s takes tiles s, s + S, s + 2S, ...
// Which tiles a slot accumulates is fixed by the thread count alone, so
// per-slot reductions give the same bits on every run.
template <typename F>
void ForEachTile(int64_t num_tiles, int slots, F&& f) {
  at::parallel_for(0, slots, 1, [&](int64_t begin, int64_t end) {
    for (int64_t s = begin; s < end; ++s) {
      for (int64_t t = s; t < num_tiles; t += slots) f(static_cast<int>(s), t);
    }
  });
}

inline int TileSlots(int64_t num_tiles) {
  return static_cast<int>(std::max<int64_t>(1, std::min<int64_t>(at::get_num_threads(), num_tiles)));
}

// The rows [*r0, *r1] of a tile starting at pixel row y0 where a Gaussian can
// reach alpha >= 1/255: |dy| <= sqrt(2 ln(255 o) cov_yy), cov = inverse(conic).
// False when it reaches none of them.
template <typename T>
bool RowBounds(T my, T a, T b, T c, T opacity, int y0, int* r0, int* r1) {
  const double level = 2.0 * std::log(double(opacity) / kMinAlpha);
  if (!(level >= 0)) return false;
  const double det = double(a) * c - double(b) * b;
  *r0 = 0;
  *r1 = kTile - 1;
  if (det > 0 && a > 0) {
    const double extent = std::sqrt(level * double(a) / det) + 1.0;  // a pixel of slack for rounding
    if (std::isfinite(extent)) {
      const double lo = std::ceil(double(my) - extent) - y0, hi = std::floor(double(my) + extent) - y0;
      if (hi < 0 || lo > kTile - 1) return false;
      *r0 = static_cast<int>(std::max(lo, 0.0));
      *r1 = static_cast<int>(std::min(hi, double(kTile - 1)));
    }
  }
  return true;
}

}  // namespace headforge::splat::cpu
