// Launchers of the CUDA kernels (splat_cuda.cu), on raw device pointers and
// free of LibTorch, so that nvcc never compiles LibTorch's headers. The
// tensors, type dispatch and streams are splat_cuda.cc's. Each returns the
// launch's error (cudaSuccess when it was queued). Instantiated for float and
// double. Internal to avatar/.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "avatar/splat/splat_params.h"

namespace headforge::splat::cuda_kernels {

template <typename T>
cudaError_t ProjectForward(const T* means, const T* quats, const T* log_scales, int64_t n,
                           const ProjectParams& params, T* means2d, T* conics, T* depths,
                           int32_t* radii, cudaStream_t stream);

template <typename T>
cudaError_t ProjectBackward(const T* means, const T* quats, const T* log_scales,
                            const int32_t* radii, int64_t n, const ProjectParams& params,
                            const T* v_means2d, const T* v_conics, const T* v_depths, T* v_means,
                            T* v_quats, T* v_log_scales, cudaStream_t stream);

// How many tiles each Gaussian's 3-sigma square covers ([n], in index order).
template <typename T>
cudaError_t CountTiles(const T* means2d, const int32_t* radii, int64_t n, int tiles_x, int tiles_y,
                       int64_t* counts, cudaStream_t stream);

// One (tile, Gaussian) entry per covered tile: Gaussian order[p] writes its
// entries from offsets[p], tiles in row-major order.
template <typename T>
cudaError_t EmitTileEntries(const T* means2d, const int32_t* radii, const int64_t* order,
                            const int64_t* offsets, int64_t n, int tiles_x, int tiles_y,
                            int32_t* tile_keys, int32_t* gaussian_ids, cudaStream_t stream);

// Composites every tile's list, as the CPU kernel: image [C, H, W],
// transmittance and last [H, W].
template <typename T>
cudaError_t RasterizeForward(const T* means2d, const T* conics, const T* features,
                             const T* opacities, const T* background, const int32_t* tile_offsets,
                             const int32_t* gaussian_ids, int channels, int width, int height,
                             T* image, T* transmittance, int32_t* last, cudaStream_t stream);

// Gradients per list entry: entry_grads [M, kGradFeatures + C], columns as
// GradientColumn (splat_params.h), zeroed by the caller; entries a tile never
// reached stay zero. Each entry is written by one block, in a fixed order.
template <typename T>
cudaError_t RasterizeBackward(const T* means2d, const T* conics, const T* features,
                              const T* opacities, const T* background, const int32_t* tile_offsets,
                              const int32_t* gaussian_ids, int channels, int width, int height,
                              const T* transmittance, const int32_t* last, const T* v_image,
                              const T* v_alpha, T* entry_grads, cudaStream_t stream);

// out[g] = sum of entry_grads[entries[j]] for j in [starts[g], starts[g + 1]),
// in that order (so the sums have the same bits on every run).
template <typename T>
cudaError_t SumEntriesPerGaussian(const T* entry_grads, const int64_t* entries,
                                  const int64_t* starts, int64_t n, int stride, T* out,
                                  cudaStream_t stream);

}  // namespace headforge::splat::cuda_kernels
