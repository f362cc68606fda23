// CPU backward of RasterizeGaussians. Each tile walks its list back to front
// from the last entry any of its pixels used, recovering each pixel's
// transmittance by division and keeping the colour composited behind the
// current Gaussian. Per-Gaussian gradients are summed into one buffer per
// schedule slot (ForEachTile), and the slots are added in a fixed order.
#include <vector>

#include "avatar/splat_kernels.h"
#include "avatar/splat_raster_cpu.h"

namespace headforge::splat::cpu {
namespace {

// Layout of one Gaussian's row in a slot's gradient buffer.
enum : int { kGradMx, kGradMy, kGradA, kGradB, kGradC, kGradO, kGradFeatures };

template <typename T>
struct TileScratch {
  std::vector<T> behind;  // [C][256] colour composited behind the current Gaussian
  std::vector<T> v_pix;   // [C][256] d loss / d image
};

template <typename T>
void BackwardTile(int64_t tile, int tiles_x, int width, int height, int channels,
                  const T* means2d, const T* conics, const T* features, const T* opacities,
                  const T* background, const int32_t* offsets, const int32_t* ids,
                  const T* transmittance, const int32_t* last, const T* v_image, const T* v_alpha,
                  TileScratch<T>& scratch, T* grads /* [N][6 + C] */) {
  const int x0 = static_cast<int>(tile % tiles_x) * kTile;
  const int y0 = static_cast<int>(tile / tiles_x) * kTile;
  const int cols = std::min(kTile, width - x0), rows = std::min(kTile, height - y0);
  const int64_t plane = int64_t(width) * height;
  alignas(64) T trans[kTilePixels];
  alignas(64) T v_alpha_final[kTilePixels];  // d loss / d alpha_i through the alpha output, times (1 - alpha_i)
  alignas(64) int32_t count[kTilePixels];
  T* behind = scratch.behind.data();
  T* v_pix = scratch.v_pix.data();
  int32_t max_count = 0;
  for (int p = 0; p < kTilePixels; ++p) {
    trans[p] = 1;
    count[p] = 0;
    v_alpha_final[p] = 0;
  }
  std::fill_n(v_pix, int64_t(channels) * kTilePixels, T(0));
  for (int row = 0; row < rows; ++row) {
    const int64_t pixel = int64_t(y0 + row) * width + x0;
    for (int j = 0; j < cols; ++j) {
      const int p = row * kTile + j;
      trans[p] = transmittance[pixel + j];
      count[p] = last[pixel + j];
      // alpha = 1 - T_final: d alpha / d alpha_i = T_final / (1 - alpha_i).
      v_alpha_final[p] = v_alpha[pixel + j] * trans[p];
      max_count = std::max(max_count, count[p]);
    }
    for (int ch = 0; ch < channels; ++ch) {
      const T* in = v_image + ch * plane + pixel;
      T* out = v_pix + ch * kTilePixels + row * kTile;
      for (int j = 0; j < cols; ++j) out[j] = in[j];
    }
  }
  for (int ch = 0; ch < channels; ++ch) {
    const T bg = background[ch];
    T* b = behind + ch * kTilePixels;
    for (int p = 0; p < kTilePixels; ++p) b[p] = trans[p] * bg;
  }

  const int32_t begin = offsets[tile];
  const T min_alpha = static_cast<T>(kMinAlpha), max_alpha = static_cast<T>(kMaxAlpha);
  alignas(64) T weight[kTile], inv_one_minus[kTile], t_before[kTile], v_alpha_pix[kTile];
  alignas(64) T dx_lane[kTile], vis_lane[kTile];
  alignas(64) int32_t use_lane[kTile];
  for (int32_t index = max_count - 1; index >= 0; --index) {
    const int32_t g = ids[begin + index];
    const T mx = means2d[2 * g] - x0, my = means2d[2 * g + 1] - y0;
    const T a = conics[3 * g], b = conics[3 * g + 1], c = conics[3 * g + 2];
    const T o = opacities[g];
    int r0, r1;
    if (!RowBounds(my + y0, a, b, c, o, y0, &r0, &r1)) continue;
    const T* f = features + int64_t(g) * channels;
    T* grad = grads + int64_t(g) * (kGradFeatures + channels);
    T g_mx = 0, g_my = 0, g_a = 0, g_b = 0, g_c = 0, g_o = 0;
    for (int row = r0; row <= r1; ++row) {
      const T dy = my - row;
      const T cdy2 = c * dy * dy, bdy = b * dy;
      T* t_row = trans + row * kTile;
      const int32_t* n_row = count + row * kTile;
      for (int j = 0; j < kTile; ++j) {
        const T dx = mx - j;
        const T sigma = T(0.5) * (a * dx * dx + cdy2) + bdy * dx;
        const T vis = Exp(-sigma);
        const T alpha = std::min(max_alpha, o * vis);
        const bool use = index < n_row[j] && sigma >= 0 && alpha >= min_alpha;
        const T r = T(1) / (T(1) - alpha);
        const T t_i = use ? t_row[j] * r : t_row[j];
        t_row[j] = t_i;
        weight[j] = use ? alpha * t_i : T(0);
        inv_one_minus[j] = r;
        t_before[j] = t_i;
        // Only unclamped alphas pass a gradient to opacity and sigma.
        use_lane[j] = use && o * vis < max_alpha;
        dx_lane[j] = dx;
        vis_lane[j] = vis;
        v_alpha_pix[j] = v_alpha_final[row * kTile + j] * r;
      }
      for (int ch = 0; ch < channels; ++ch) {
        const T fc = f[ch];
        const T* v_row = v_pix + ch * kTilePixels + row * kTile;
        T* b_row = behind + ch * kTilePixels + row * kTile;
        T g_f = 0;
        for (int j = 0; j < kTile; ++j) {
          g_f += weight[j] * v_row[j];
          v_alpha_pix[j] += v_row[j] * (fc * t_before[j] - b_row[j] * inv_one_minus[j]);
          b_row[j] += fc * weight[j];
        }
        grad[kGradFeatures + ch] += g_f;
      }
      for (int j = 0; j < kTile; ++j) {
        const T dx = dx_lane[j];
        const T v_o = use_lane[j] ? v_alpha_pix[j] * vis_lane[j] : T(0);
        // d alpha / d sigma = -o vis.
        const T v_sigma = -v_o * o;
        g_o += v_o;
        g_a += v_sigma * T(0.5) * dx * dx;
        g_b += v_sigma * dx * dy;
        g_c += v_sigma * T(0.5) * dy * dy;
        g_mx += v_sigma * (a * dx + b * dy);
        g_my += v_sigma * (b * dx + c * dy);
      }
    }
    grad[kGradMx] += g_mx;
    grad[kGradMy] += g_my;
    grad[kGradA] += g_a;
    grad[kGradB] += g_b;
    grad[kGradC] += g_c;
    grad[kGradO] += g_o;
  }
}

}  // namespace

void RasterizeBackward(const torch::Tensor& means2d, const torch::Tensor& conics,
                       const torch::Tensor& features, const torch::Tensor& opacities,
                       const torch::Tensor& background, const torch::Tensor& tile_offsets,
                       const torch::Tensor& gaussian_ids, int width, int height,
                       const torch::Tensor& transmittance, const torch::Tensor& last,
                       const torch::Tensor& v_image, const torch::Tensor& v_alpha,
                       torch::Tensor& v_means2d, torch::Tensor& v_conics,
                       torch::Tensor& v_features, torch::Tensor& v_opacities) {
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
      s.behind.resize(size_t(channels) * kTilePixels);
      s.v_pix.resize(size_t(channels) * kTilePixels);
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
  const auto total = slots == 1 ? grads[0] : grads.sum(0);
  v_means2d = total.slice(1, kGradMx, kGradMy + 1).contiguous();
  v_conics = total.slice(1, kGradA, kGradC + 1).contiguous();
  v_opacities = total.select(1, kGradO).contiguous();
  v_features = total.slice(1, kGradFeatures, stride).contiguous();
}

}  // namespace headforge::splat::cpu
