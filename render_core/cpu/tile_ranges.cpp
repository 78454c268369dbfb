// Stage 4: per-tile [start, end) ranges of the sorted render list (mirrors the CUDA kernel).
#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

void identify_tile_ranges(const RenderList& list, const TileGrid& grid, TileRanges& ranges) {
  ranges.assign(static_cast<std::size_t>(grid.tile_count()), glm::uvec2(0u));
  const std::size_t n = list.keys.size();
  for (std::size_t i = 0; i < n; ++i) {
    const uint32_t tile = list.packing.tile_of(list.keys[i]);
    if (i == 0 || list.packing.tile_of(list.keys[i - 1]) != tile) ranges[tile].x = static_cast<uint32_t>(i);
    if (i + 1 == n || list.packing.tile_of(list.keys[i + 1]) != tile) ranges[tile].y = static_cast<uint32_t>(i + 1);
  }
}

}  // namespace catgs::cpu
