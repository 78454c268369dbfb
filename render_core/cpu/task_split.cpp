// Load-aware task splitting (paper sec. 3.4, supplementary Alg. 1): the plan of rasterization
// tasks. Mirrors the GPU's split plan so both rasterize the same slices.
#include <algorithm>

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

void plan_slices(const TileRanges& ranges, std::size_t list_length, bool split, std::vector<TileSlice>& slices,
                 std::size_t min_slice, std::uint32_t first_tile, std::uint32_t end_tile) {
  slices.clear();
  const std::size_t tiles = ranges.size();
  // Slice length l = L / t (at least 1, at least min_slice); a tile over 2l entries is a heavy tile.
  // A pass of a frame drawn in passes gives the whole frame's L and grid, so l is the one-pass l.
  const std::size_t avg = std::max(min_slice, tiles > 0 ? std::max<std::size_t>(1, list_length / tiles) : 1);
  for (std::size_t t = first_tile; t < std::min<std::size_t>(tiles, end_tile); ++t) {
    const unsigned begin = ranges[t].x, end = ranges[t].y;
    const std::size_t load = end - begin;
    if (!split || load <= 2 * avg) {
      slices.push_back({static_cast<unsigned>(t), begin, end, 0});
      continue;
    }
    // n slices of l entries, the first taking the remainder (so it is the largest, never tiny).
    const std::size_t n = load / avg;
    const std::size_t first = load - (n - 1) * avg;
    unsigned at = begin;
    for (std::size_t k = 0; k < n; ++k) {
      const unsigned size = static_cast<unsigned>(k == 0 ? first : avg);
      slices.push_back({static_cast<unsigned>(t), at, at + size, static_cast<unsigned>(k)});
      at += size;
    }
  }
}

}  // namespace catgs::cpu
