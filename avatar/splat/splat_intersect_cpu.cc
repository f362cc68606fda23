// CPU kernel of IntersectTiles: a counting pass builds the per-tile lists in
// Gaussian order, then each tile sorts its own list by depth in parallel.
#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "avatar/splat/splat_kernels.h"

namespace headforge::splat::cpu {
namespace {

struct TileRange {
  int x0, x1, y0, y1;  // inclusive; empty when x0 > x1
};

template <typename T>
TileRange RangeOf(const T* mean2d, int radius, int tiles_x, int tiles_y) {
  if (radius <= 0) return {1, 0, 1, 0};
  const double r = radius;
  const int x0 = static_cast<int>(std::floor((mean2d[0] - r) / kSplatTileSize));
  const int x1 = static_cast<int>(std::floor((mean2d[0] + r) / kSplatTileSize));
  const int y0 = static_cast<int>(std::floor((mean2d[1] - r) / kSplatTileSize));
  const int y1 = static_cast<int>(std::floor((mean2d[1] + r) / kSplatTileSize));
  return {std::max(x0, 0), std::min(x1, tiles_x - 1), std::max(y0, 0), std::min(y1, tiles_y - 1)};
}

}  // namespace

std::pair<torch::Tensor, torch::Tensor> IntersectTiles(const torch::Tensor& means2d,
                                                       const torch::Tensor& radii,
                                                       const torch::Tensor& depths, int tiles_x,
                                                       int tiles_y) {
  const int64_t n = means2d.size(0);
  const int64_t num_tiles = int64_t(tiles_x) * tiles_y;
  auto offsets = torch::zeros({num_tiles + 1}, torch::kInt32);
  int32_t* off = offsets.data_ptr<int32_t>();
  torch::Tensor ids;
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "IntersectTiles", [&] {
    const scalar_t* m = means2d.data_ptr<scalar_t>();
    const scalar_t* d = depths.data_ptr<scalar_t>();
    const int32_t* r = radii.data_ptr<int32_t>();
    std::vector<TileRange> ranges(n);
    at::parallel_for(0, n, 4096, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) ranges[i] = RangeOf(m + 2 * i, r[i], tiles_x, tiles_y);
    });
    // Counts, then exclusive prefix sums (in 64 bits: a count past int32 is an error).
    std::vector<int64_t> count(num_tiles + 1, 0);
    for (int64_t i = 0; i < n; ++i) {
      const TileRange& t = ranges[i];
      for (int y = t.y0; y <= t.y1; ++y) {
        for (int x = t.x0; x <= t.x1; ++x) ++count[int64_t(y) * tiles_x + x];
      }
    }
    int64_t total = 0;
    for (int64_t t = 0; t < num_tiles; ++t) {
      const int64_t c = count[t];
      count[t] = total;
      total += c;
    }
    TORCH_CHECK(total < (int64_t(1) << 31), "IntersectTiles: ", total,
                " Gaussian-tile pairs do not fit 32-bit offsets; render at a lower resolution "
                "or with fewer, smaller Gaussians");
    for (int64_t t = 0; t < num_tiles; ++t) off[t] = static_cast<int32_t>(count[t]);
    off[num_tiles] = static_cast<int32_t>(total);
    ids = torch::empty({total}, torch::kInt32);
    int32_t* out = ids.data_ptr<int32_t>();
    for (int64_t i = 0; i < n; ++i) {
      const TileRange& t = ranges[i];
      for (int y = t.y0; y <= t.y1; ++y) {
        for (int x = t.x0; x <= t.x1; ++x) out[count[int64_t(y) * tiles_x + x]++] = int32_t(i);
      }
    }
    // Near to far; equal depths keep index order, so the order is deterministic.
    at::parallel_for(0, num_tiles, 16, [&](int64_t begin, int64_t end) {
      for (int64_t t = begin; t < end; ++t) {
        std::stable_sort(out + off[t], out + off[t + 1],
                         [d](int32_t a, int32_t b) { return d[a] < d[b]; });
      }
    });
  });
  return {offsets, ids};
}

}  // namespace headforge::splat::cpu
