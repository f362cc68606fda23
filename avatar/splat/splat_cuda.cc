// The CUDA backend's entry points (splat_kernels.h, namespace cuda): type
// dispatch, scratch tensors and the current stream around the raw kernels of
// splat_cuda.cu. Sorting uses LibTorch's stable sort, so the tile lists are
// the CPU's exactly: by depth, equal depths by index. Compiled only when the
// LibTorch found has CUDA.
#include <ATen/cuda/CUDAContext.h>
#include <c10/cuda/CUDAGuard.h>
#include <torch/torch.h>

#include "avatar/splat/splat_cuda_kernels.h"
#include "avatar/splat/splat_kernels.h"

namespace headforge::splat::cuda {
namespace {

void Check(cudaError_t error, const char* op) {
  TORCH_CHECK(error == cudaSuccess, op, ": CUDA kernel failed: ", cudaGetErrorString(error));
}

cudaStream_t Stream() { return at::cuda::getCurrentCUDAStream().stream(); }

}  // namespace

void ProjectForward(const torch::Tensor& means, const torch::Tensor& quats,
                    const torch::Tensor& log_scales, const ProjectParams& params,
                    torch::Tensor& means2d, torch::Tensor& conics, torch::Tensor& depths,
                    torch::Tensor& radii) {
  const c10::cuda::CUDAGuard guard(means.device());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "ProjectForward", [&] {
    Check(
        cuda_kernels::ProjectForward<scalar_t>(
            means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(), log_scales.data_ptr<scalar_t>(),
            means.size(0), params, means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(),
            depths.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(), Stream()),
        "ProjectGaussians");
  });
}

void ProjectBackward(const torch::Tensor& means, const torch::Tensor& quats,
                     const torch::Tensor& log_scales, const torch::Tensor& radii,
                     const ProjectParams& params, const torch::Tensor& v_means2d,
                     const torch::Tensor& v_conics, const torch::Tensor& v_depths,
                     torch::Tensor& v_means, torch::Tensor& v_quats, torch::Tensor& v_log_scales) {
  const c10::cuda::CUDAGuard guard(means.device());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "ProjectBackward", [&] {
    Check(cuda_kernels::ProjectBackward<scalar_t>(
              means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(),
              log_scales.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(), means.size(0), params,
              v_means2d.data_ptr<scalar_t>(), v_conics.data_ptr<scalar_t>(),
              v_depths.data_ptr<scalar_t>(), v_means.data_ptr<scalar_t>(),
              v_quats.data_ptr<scalar_t>(), v_log_scales.data_ptr<scalar_t>(), Stream()),
          "ProjectGaussians backward");
  });
}

std::pair<torch::Tensor, torch::Tensor> IntersectTiles(const torch::Tensor& means2d,
                                                       const torch::Tensor& radii,
                                                       const torch::Tensor& depths, int tiles_x,
                                                       int tiles_y) {
  const c10::cuda::CUDAGuard guard(means2d.device());
  const int64_t n = means2d.size(0);
  const int64_t num_tiles = int64_t(tiles_x) * tiles_y;
  const auto long_options = means2d.options().dtype(torch::kInt64);
  const auto int_options = means2d.options().dtype(torch::kInt32);
  // Gaussians near to far (equal depths in index order), then each one's
  // entries in that order; a stable sort by tile keeps it within every tile.
  const torch::Tensor order =
      std::get<1>(torch::sort(depths, /*stable=*/true, /*dim=*/0, /*descending=*/false));
  auto counts = torch::empty({n}, long_options);
  torch::Tensor keys, ids;
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "IntersectTiles", [&] {
    Check(cuda_kernels::CountTiles<scalar_t>(means2d.data_ptr<scalar_t>(),
                                             radii.data_ptr<int32_t>(), n, tiles_x, tiles_y,
                                             counts.data_ptr<int64_t>(), Stream()),
          "IntersectTiles");
    const torch::Tensor ordered_counts = counts.index_select(0, order);
    const torch::Tensor ends = ordered_counts.cumsum(0);
    const int64_t total = n == 0 ? 0 : ends[n - 1].item<int64_t>();
    TORCH_CHECK(total < (int64_t(1) << 31), "IntersectTiles: ", total,
                " Gaussian-tile pairs do not fit 32-bit offsets; render at a lower resolution "
                "or with fewer, smaller Gaussians");
    const torch::Tensor starts = ends - ordered_counts;
    keys = torch::empty({total}, int_options);
    ids = torch::empty({total}, int_options);
    Check(cuda_kernels::EmitTileEntries<scalar_t>(
              means2d.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(), order.data_ptr<int64_t>(),
              starts.data_ptr<int64_t>(), n, tiles_x, tiles_y, keys.data_ptr<int32_t>(),
              ids.data_ptr<int32_t>(), Stream()),
          "IntersectTiles");
  });
  const auto by_key = torch::sort(keys, /*stable=*/true, /*dim=*/0, /*descending=*/false);
  const torch::Tensor& sorted_keys = std::get<0>(by_key);
  const torch::Tensor& by_tile = std::get<1>(by_key);
  const torch::Tensor gaussian_ids = ids.index_select(0, by_tile);
  const torch::Tensor tile_offsets = torch::searchsorted(
      sorted_keys, torch::arange(num_tiles + 1, int_options), /*out_int32=*/true);
  return {tile_offsets, gaussian_ids};
}

void RasterizeForward(const torch::Tensor& means2d, const torch::Tensor& conics,
                      const torch::Tensor& features, const torch::Tensor& opacities,
                      const torch::Tensor& background, const torch::Tensor& tile_offsets,
                      const torch::Tensor& gaussian_ids, int width, int height,
                      torch::Tensor& image, torch::Tensor& transmittance, torch::Tensor& last) {
  const c10::cuda::CUDAGuard guard(means2d.device());
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "RasterizeForward", [&] {
    Check(cuda_kernels::RasterizeForward<scalar_t>(
              means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(),
              features.data_ptr<scalar_t>(), opacities.data_ptr<scalar_t>(),
              background.data_ptr<scalar_t>(), tile_offsets.data_ptr<int32_t>(),
              gaussian_ids.data_ptr<int32_t>(), static_cast<int>(features.size(1)), width, height,
              image.data_ptr<scalar_t>(), transmittance.data_ptr<scalar_t>(),
              last.data_ptr<int32_t>(), Stream()),
          "RasterizeGaussians");
  });
}

torch::Tensor RasterizeBackward(const torch::Tensor& means2d, const torch::Tensor& conics,
                                const torch::Tensor& features, const torch::Tensor& opacities,
                                const torch::Tensor& background, const torch::Tensor& tile_offsets,
                                const torch::Tensor& gaussian_ids, int width, int height,
                                const torch::Tensor& transmittance, const torch::Tensor& last,
                                const torch::Tensor& v_image, const torch::Tensor& v_alpha) {
  const c10::cuda::CUDAGuard guard(means2d.device());
  const int64_t n = means2d.size(0);
  const int64_t entries = gaussian_ids.numel();
  const int channels = static_cast<int>(features.size(1));
  const int stride = kGradFeatures + channels;
  auto entry_grads = torch::zeros({entries, stride}, means2d.options());
  auto total = torch::empty({n, stride}, means2d.options());
  // Each Gaussian's entries, in list order: its rows are summed in that order.
  const auto by_id = torch::sort(gaussian_ids, /*stable=*/true, /*dim=*/0, /*descending=*/false);
  const torch::Tensor& sorted_ids = std::get<0>(by_id);
  const torch::Tensor& by_gaussian = std::get<1>(by_id);
  const torch::Tensor starts = torch::searchsorted(
      sorted_ids, torch::arange(n + 1, gaussian_ids.options()), /*out_int32=*/false);
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "RasterizeBackward", [&] {
    Check(cuda_kernels::RasterizeBackward<scalar_t>(
              means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(),
              features.data_ptr<scalar_t>(), opacities.data_ptr<scalar_t>(),
              background.data_ptr<scalar_t>(), tile_offsets.data_ptr<int32_t>(),
              gaussian_ids.data_ptr<int32_t>(), channels, width, height,
              transmittance.data_ptr<scalar_t>(), last.data_ptr<int32_t>(),
              v_image.data_ptr<scalar_t>(), v_alpha.data_ptr<scalar_t>(),
              entry_grads.data_ptr<scalar_t>(), Stream()),
          "RasterizeGaussians backward");
    Check(cuda_kernels::SumEntriesPerGaussian<scalar_t>(
              entry_grads.data_ptr<scalar_t>(), by_gaussian.data_ptr<int64_t>(),
              starts.data_ptr<int64_t>(), n, stride, total.data_ptr<scalar_t>(), Stream()),
          "RasterizeGaussians backward");
  });
  return total;
}

}  // namespace headforge::splat::cuda
