// CPU forward of RasterizeGaussians. Each tile keeps its 16x16 pixels'
// transmittance and channel sums in small arrays and walks its depth-sorted
// list once; the per-pixel work is written as straight loops over a tile row
// (16 lanes) with selects instead of branches, so it vectorises.
#include <vector>

#include "avatar/splat_kernels.h"
#include "avatar/splat_raster_cpu.h"

namespace headforge::splat::cpu {
namespace {

template <typename T>
void ForwardTile(int64_t tile, int tiles_x, int width, int height, int channels, const T* means2d,
                 const T* conics, const T* features, const T* opacities, const T* background,
                 const int32_t* offsets, const int32_t* ids, T* image, T* transmittance,
                 int32_t* last, T* acc /* [C][256] scratch */) {
  const int x0 = static_cast<int>(tile % tiles_x) * kTile;
  const int y0 = static_cast<int>(tile / tiles_x) * kTile;
  alignas(64) T trans[kTilePixels];
  alignas(64) int32_t count[kTilePixels];
  alignas(64) int32_t done[kTilePixels];
  alignas(64) T weight[kTile];
  int remaining = 0;
  for (int p = 0; p < kTilePixels; ++p) {
    const bool inside = x0 + p % kTile < width && y0 + p / kTile < height;
    trans[p] = 1;
    count[p] = 0;
    done[p] = inside ? 0 : 1;
    remaining += inside;
  }
  std::fill_n(acc, int64_t(channels) * kTilePixels, T(0));

  const int32_t begin = offsets[tile], end = offsets[tile + 1];
  const T min_alpha = static_cast<T>(kMinAlpha), max_alpha = static_cast<T>(kMaxAlpha);
  const T min_trans = static_cast<T>(kMinTransmittance);
  for (int32_t k = begin; k < end; ++k) {
    // Every pixel finished: the rest of the list cannot contribute.
    if (((k - begin) & 31) == 31) {
      int open = 0;
      for (int p = 0; p < kTilePixels; ++p) open += done[p] == 0;
      if (open == 0) break;
    }
    const int32_t g = ids[k];
    const T mx = means2d[2 * g] - x0, my = means2d[2 * g + 1] - y0;
    const T a = conics[3 * g], b = conics[3 * g + 1], c = conics[3 * g + 2];
    const T o = opacities[g];
    int r0, r1;
    if (!RowBounds(my + y0, a, b, c, o, y0, &r0, &r1)) continue;
    const T* f = features + int64_t(g) * channels;
    const int32_t index = k - begin + 1;
    for (int row = r0; row <= r1; ++row) {
      const T dy = my - row;
      const T cdy2 = c * dy * dy, bdy = b * dy;
      T* t_row = trans + row * kTile;
      int32_t* n_row = count + row * kTile;
      int32_t* d_row = done + row * kTile;
      for (int j = 0; j < kTile; ++j) {
        const T dx = mx - j;
        const T sigma = T(0.5) * (a * dx * dx + cdy2) + bdy * dx;
        const T alpha = std::min(max_alpha, o * Exp(-sigma));
        const bool valid = sigma >= 0 && alpha >= min_alpha && d_row[j] == 0;
        const T t_next = t_row[j] * (1 - alpha);
        const bool stop = valid && t_next < min_trans;
        const bool use = valid && !stop;
        weight[j] = use ? alpha * t_row[j] : T(0);
        t_row[j] = use ? t_next : t_row[j];
        n_row[j] = use ? index : n_row[j];
        d_row[j] = stop ? 1 : d_row[j];
      }
      for (int ch = 0; ch < channels; ++ch) {
        const T fc = f[ch];
        T* a_row = acc + ch * kTilePixels + row * kTile;
        for (int j = 0; j < kTile; ++j) a_row[j] += weight[j] * fc;
      }
    }
  }

  const int cols = std::min(kTile, width - x0), rows = std::min(kTile, height - y0);
  const int64_t plane = int64_t(width) * height;
  for (int row = 0; row < rows; ++row) {
    const int64_t pixel = int64_t(y0 + row) * width + x0;
    for (int j = 0; j < cols; ++j) {
      transmittance[pixel + j] = trans[row * kTile + j];
      last[pixel + j] = count[row * kTile + j];
    }
    for (int ch = 0; ch < channels; ++ch) {
      const T bg = background[ch];
      const T* a_row = acc + ch * kTilePixels + row * kTile;
      T* out = image + ch * plane + pixel;
      for (int j = 0; j < cols; ++j) out[j] = a_row[j] + trans[row * kTile + j] * bg;
    }
  }
}

}  // namespace

void RasterizeForward(const torch::Tensor& means2d, const torch::Tensor& conics,
                      const torch::Tensor& features, const torch::Tensor& opacities,
                      const torch::Tensor& background, const torch::Tensor& tile_offsets,
                      const torch::Tensor& gaussian_ids, int width, int height,
                      torch::Tensor& image, torch::Tensor& transmittance, torch::Tensor& last) {
  const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t num_tiles = int64_t(tiles_x) * tiles_y;
  const int channels = static_cast<int>(features.size(1));
  const int slots = TileSlots(num_tiles);
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "RasterizeForward", [&] {
    std::vector<std::vector<scalar_t>> scratch(slots);
    for (auto& s : scratch) s.resize(size_t(channels) * kTilePixels);
    ForEachTile(num_tiles, slots, [&](int slot, int64_t tile) {
      ForwardTile<scalar_t>(tile, tiles_x, width, height, channels, means2d.data_ptr<scalar_t>(),
                            conics.data_ptr<scalar_t>(), features.data_ptr<scalar_t>(),
                            opacities.data_ptr<scalar_t>(), background.data_ptr<scalar_t>(),
                            tile_offsets.data_ptr<int32_t>(), gaussian_ids.data_ptr<int32_t>(),
                            image.data_ptr<scalar_t>(), transmittance.data_ptr<scalar_t>(),
                            last.data_ptr<int32_t>(), scratch[slot].data());
    });
  });
}

}  // namespace headforge::splat::cpu
