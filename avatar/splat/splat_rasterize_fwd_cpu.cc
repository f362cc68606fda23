// CPU forward of RasterizeGaussians. Each tile keeps its 16x16 pixels'
// transmittance and channel sums in small arrays, one 16-lane vector per tile
// row, and walks its depth-sorted list once; the per-pixel work is lane-wise
// selects instead of branches.
#include <vector>

#include "avatar/splat/splat_kernels.h"
#include "avatar/splat/splat_raster_cpu.h"

namespace headforge::splat::cpu {
namespace {

template <typename T>
void ForwardTile(int64_t tile, int tiles_x, int width, int height, int channels, const T* means2d,
                 const T* conics, const T* features, const T* opacities, const T* background,
                 const int32_t* offsets, const int32_t* ids, T* image, T* transmittance,
                 int32_t* last, typename Lanes<T>::Vec* acc /* [C][16] scratch */) {
  using V = typename Lanes<T>::Vec;
  using M = typename Lanes<T>::Mask;
  const int x0 = static_cast<int>(tile % tiles_x) * kTile;
  const int y0 = static_cast<int>(tile / tiles_x) * kTile;
  const int cols = std::min(kTile, width - x0), rows = std::min(kTile, height - y0);
  const V lane = LaneIndex<V>();
  V trans[kTile];
  M count[kTile], done[kTile];
  // Pixels outside the image start finished.
  const M outside_cols = lane >= T(cols);
  for (int row = 0; row < kTile; ++row) {
    trans[row] = Splat<V>(T(1));
    count[row] = M{};
    done[row] = row < rows ? outside_cols : ~M{};
  }
  std::fill_n(acc, int64_t(channels) * kTile, V{});

  const int32_t begin = offsets[tile], end = offsets[tile + 1];
  const T min_alpha = static_cast<T>(kMinAlpha), max_alpha = static_cast<T>(kMaxAlpha);
  const T min_trans = static_cast<T>(kMinTransmittance);
  for (int32_t k = begin; k < end; ++k) {
    // Every pixel finished: the rest of the list cannot contribute.
    if (((k - begin) & 15) == 15) {
      M open = M{};
      for (int row = 0; row < kTile; ++row) open |= ~done[row];
      if (!AnyLane(open)) break;
    }
    const int32_t g = ids[k];
    const T mx = means2d[2 * g] - x0, my = means2d[2 * g + 1] - y0;
    const T a = conics[3 * g], b = conics[3 * g + 1], c = conics[3 * g + 2];
    const T o = opacities[g];
    int r0, r1;
    if (!RowBounds(my + y0, a, b, c, o, y0, &r0, &r1)) continue;
    const T* f = features + int64_t(g) * channels;
    const int32_t index = k - begin + 1;
    const V dx = mx - lane;
    const V adx2 = a * dx * dx;
    for (int row = r0; row <= r1; ++row) {
      const T dy = my - row;
      const V sigma = T(0.5) * (adx2 + c * dy * dy) + (b * dy) * dx;
      const V alpha = Min(o * Exp(-sigma), Splat<V>(max_alpha));
      const M valid = (sigma >= T(0)) & (alpha >= min_alpha) & ~done[row];
      const V t = trans[row];
      const V t_next = t * (T(1) - alpha);
      const M stop = valid & (t_next < min_trans);
      const M use = valid & ~stop;
      if (!AnyLane(valid)) continue;
      const V w = Select(use, alpha * t, V{});
      trans[row] = Select(use, t_next, t);
      count[row] = Select(use, Splat<M>(index), count[row]);
      done[row] |= stop;
      V* a_row = acc + row;
      for (int ch = 0; ch < channels; ++ch) a_row[ch * kTile] += w * f[ch];
    }
  }

  const int64_t plane = int64_t(width) * height;
  for (int row = 0; row < rows; ++row) {
    const int64_t pixel = int64_t(y0 + row) * width + x0;
    for (int j = 0; j < cols; ++j) {
      transmittance[pixel + j] = trans[row][j];
      last[pixel + j] = static_cast<int32_t>(count[row][j]);
    }
    for (int ch = 0; ch < channels; ++ch) {
      const V value = acc[ch * kTile + row] + trans[row] * background[ch];
      T* out = image + ch * plane + pixel;
      for (int j = 0; j < cols; ++j) out[j] = value[j];
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
    using V = typename Lanes<scalar_t>::Vec;
    std::vector<std::vector<V>> scratch(slots);
    for (auto& s : scratch) s.resize(size_t(channels) * kTile);
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
