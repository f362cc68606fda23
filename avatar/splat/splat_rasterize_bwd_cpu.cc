// CPU backward of RasterizeGaussians. Each tile walks its list back to front
// from the last entry any of its pixels used, recovering each pixel's
// transmittance by division and keeping the colour composited behind the
// current Gaussian, one 16-lane vector per tile row. Per-Gaussian gradients
// are summed into one buffer per schedule slot (ForEachTile), and the slots
// are added in a fixed order.
#include <vector>

#include "avatar/splat/splat_kernels.h"
#include "avatar/splat/splat_raster_cpu.h"

namespace headforge::splat::cpu {
namespace {

template <typename T>
struct TileScratch {
  using V = typename Lanes<T>::Vec;
  std::vector<V> behind;  // [C][16] colour composited behind the current Gaussian
  std::vector<V> v_pix;   // [C][16] d loss / d image
  std::vector<V> g_f;     // [C] per-Gaussian feature gradient, lane-wise
};

template <typename T>
void BackwardTile(int64_t tile, int tiles_x, int width, int height, int channels,
                  const T* means2d, const T* conics, const T* features, const T* opacities,
                  const T* background, const int32_t* offsets, const int32_t* ids,
                  const T* transmittance, const int32_t* last, const T* v_image, const T* v_alpha,
                  TileScratch<T>& scratch, T* grads /* [N][kGradFeatures + C] */) {
  using V = typename Lanes<T>::Vec;
  using M = typename Lanes<T>::Mask;
  const int x0 = static_cast<int>(tile % tiles_x) * kTile;
  const int y0 = static_cast<int>(tile / tiles_x) * kTile;
  const int cols = std::min(kTile, width - x0), rows = std::min(kTile, height - y0);
  const int64_t plane = int64_t(width) * height;
  const V lane = LaneIndex<V>();
  V trans[kTile];
  V v_alpha_final[kTile];  // d loss / d alpha output, times T_final
  M count[kTile];
  V* behind = scratch.behind.data();
  V* v_pix = scratch.v_pix.data();
  V* g_f = scratch.g_f.data();
  int32_t max_count = 0;
  for (int row = 0; row < kTile; ++row) {
    trans[row] = Splat<V>(T(1));
    v_alpha_final[row] = V{};
    count[row] = M{};
    for (int ch = 0; ch < channels; ++ch) v_pix[ch * kTile + row] = V{};
  }
  for (int row = 0; row < rows; ++row) {
    const int64_t pixel = int64_t(y0 + row) * width + x0;
    for (int j = 0; j < cols; ++j) {
      trans[row][j] = transmittance[pixel + j];
      count[row][j] = last[pixel + j];
      // alpha = 1 - T_final, so d alpha / d alpha_i = T_final / (1 - alpha_i).
      v_alpha_final[row][j] = v_alpha[pixel + j] * transmittance[pixel + j];
      max_count = std::max(max_count, last[pixel + j]);
    }
    for (int ch = 0; ch < channels; ++ch) {
      const T* in = v_image + ch * plane + pixel;
      for (int j = 0; j < cols; ++j) v_pix[ch * kTile + row][j] = in[j];
    }
  }
  for (int ch = 0; ch < channels; ++ch) {
    for (int row = 0; row < kTile; ++row) behind[ch * kTile + row] = trans[row] * background[ch];
  }

  const int32_t begin = offsets[tile];
  const T min_alpha = static_cast<T>(kMinAlpha), max_alpha = static_cast<T>(kMaxAlpha);
  for (int32_t index = max_count - 1; index >= 0; --index) {
    const int32_t g = ids[begin + index];
    const T mx = means2d[2 * g] - x0, my = means2d[2 * g + 1] - y0;
    const T a = conics[3 * g], b = conics[3 * g + 1], c = conics[3 * g + 2];
    const T o = opacities[g];
    int r0, r1;
    if (!RowBounds(my + y0, a, b, c, o, y0, &r0, &r1)) continue;
    const T* f = features + int64_t(g) * channels;
    const V dx = mx - lane;
    const V adx2 = a * dx * dx;
    const V dx2_half = T(0.5) * dx * dx;
    V g_o = V{}, g_a = V{}, g_b = V{}, g_c = V{}, g_mx = V{}, g_my = V{};
    bool touched = false;
    for (int row = r0; row <= r1; ++row) {
      const T dy = my - row;
      const V sigma = T(0.5) * (adx2 + c * dy * dy) + (b * dy) * dx;
      const V vis = Exp(-sigma);
      const V raw = o * vis;
      const V alpha = Min(raw, Splat<V>(max_alpha));
      const M use = (count[row] > index) & (sigma >= T(0)) & (alpha >= min_alpha);
      if (!AnyLane(use)) continue;
      if (!touched) {
        std::fill_n(g_f, channels, V{});
        touched = true;
      }
      const V inv = T(1) / (T(1) - alpha);
      const V t_i = Select(use, trans[row] * inv, trans[row]);
      trans[row] = t_i;
      const V w = Select(use, alpha * t_i, V{});
      // d colour_c / d alpha_i = f_c T_i - behind_c / (1 - alpha_i).
      V v_alpha_pix = v_alpha_final[row] * inv;
      for (int ch = 0; ch < channels; ++ch) {
        const V v = v_pix[ch * kTile + row];
        V& bh = behind[ch * kTile + row];
        g_f[ch] += w * v;
        v_alpha_pix += v * (f[ch] * t_i - bh * inv);
        bh += f[ch] * w;
      }
      // Only unclamped alphas pass a gradient to opacity and sigma.
      const V v_o = Select(use & (raw < max_alpha), v_alpha_pix * vis, V{});
      const V v_sigma = -o * v_o;  // d alpha / d sigma = -o vis
      g_o += v_o;
      g_a += v_sigma * dx2_half;
      g_b += v_sigma * dx * dy;
      g_c += v_sigma * (T(0.5) * dy * dy);
      g_mx += v_sigma * (a * dx + b * dy);
      g_my += v_sigma * (b * dx + c * dy);
    }
    if (!touched) continue;
    T* grad = grads + int64_t(g) * (kGradFeatures + channels);
    grad[kGradMx] += SumLanes(g_mx);
    grad[kGradMy] += SumLanes(g_my);
    grad[kGradA] += SumLanes(g_a);
    grad[kGradB] += SumLanes(g_b);
    grad[kGradC] += SumLanes(g_c);
    grad[kGradO] += SumLanes(g_o);
    for (int ch = 0; ch < channels; ++ch) grad[kGradFeatures + ch] += SumLanes(g_f[ch]);
  }
}

}  // namespace

torch::Tensor RasterizeBackward(const torch::Tensor& means2d, const torch::Tensor& conics,
                                const torch::Tensor& features, const torch::Tensor& opacities,
                                const torch::Tensor& background, const torch::Tensor& tile_offsets,
                                const torch::Tensor& gaussian_ids, int width, int height,
                                const torch::Tensor& transmittance, const torch::Tensor& last,
                                const torch::Tensor& v_image, const torch::Tensor& v_alpha) {
  const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t num_tiles = int64_t(tiles_x) * tiles_y;
  const int64_t n = means2d.size(0);
  const int channels = static_cast<int>(features.size(1));
  const int stride = kGradFeatures + channels;
  const int slots = TileSlots(num_tiles);
  // One gradient buffer per slot, added up below.
  auto grads = torch::zeros({slots, n, stride}, means2d.options());
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "RasterizeBackward", [&] {
    std::vector<TileScratch<scalar_t>> scratch(slots);
    for (auto& s : scratch) {
      s.behind.resize(size_t(channels) * kTile);
      s.v_pix.resize(size_t(channels) * kTile);
      s.g_f.resize(size_t(channels));
    }
    scalar_t* grad_data = grads.data_ptr<scalar_t>();
    ForEachTile(num_tiles, slots, [&](int slot, int64_t tile) {
      BackwardTile<scalar_t>(tile, tiles_x, width, height, channels, means2d.data_ptr<scalar_t>(),
                             conics.data_ptr<scalar_t>(), features.data_ptr<scalar_t>(),
                             opacities.data_ptr<scalar_t>(), background.data_ptr<scalar_t>(),
                             tile_offsets.data_ptr<int32_t>(), gaussian_ids.data_ptr<int32_t>(),
                             transmittance.data_ptr<scalar_t>(), last.data_ptr<int32_t>(),
                             v_image.data_ptr<scalar_t>(), v_alpha.data_ptr<scalar_t>(),
                             scratch[slot], grad_data + int64_t(slot) * n * stride);
    });
  });
  return slots == 1 ? grads[0] : grads.sum(0);
}

}  // namespace headforge::splat::cpu
