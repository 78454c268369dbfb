// Stage 3: sort the render list by [tile | depth] keys (mirrors CUB's stable radix sort in
// cuda/sort.cu), re-keyed first as the frame's packing says (forward_model/key_packing.h).
#include <algorithm>
#include <numeric>

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

void sort_render_list(RenderList& list, const fm::DepthKeyPacking& packing) {
  const std::size_t n = list.keys.size();
  // Sorting (key, value) pairs equals a stable sort by key: values are emitted in increasing
  // Gaussian index within a tile, and equal keys only occur within a tile (for the plain key,
  // only between equal depths; for a quantised one, between depths that share a code).
  std::vector<std::pair<uint64_t, uint32_t>> pairs(n);
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t plain = list.keys[i];
    pairs[i] = {packing.key64(static_cast<uint32_t>(plain >> 32), static_cast<uint32_t>(plain)), list.values[i]};
  }
  std::sort(pairs.begin(), pairs.end());
  for (std::size_t i = 0; i < n; ++i) {
    list.keys[i] = pairs[i].first;
    list.values[i] = pairs[i].second;
  }
  list.packing = packing;
}

fm::DepthKeyPacking single_sort_packing_of(const RenderList& list, const TileGrid& grid) {
  uint32_t low = 0xffffffffu, high = 0u;
  for (const uint64_t plain : list.keys) {
    const auto depth_bits = static_cast<uint32_t>(plain);
    low = std::min(low, depth_bits);
    high = std::max(high, depth_bits);
  }
  return fm::single_sort_packing(low, high, static_cast<uint32_t>(grid.tile_count()));
}

fm::DepthKeyPacking single_sort_packing_of(const ProjectedGaussians& projected, const TileGrid& grid) {
  uint32_t low = 0xffffffffu, high = 0u;
  for (std::size_t i = 0; i < projected.tiles_touched.size(); ++i) {
    if (projected.tiles_touched[i] == 0) continue;
    const uint32_t depth_bits = fm::float_bits(projected.depth[i]);  // as fm::render_key writes it
    low = std::min(low, depth_bits);
    high = std::max(high, depth_bits);
  }
  return fm::single_sort_packing(low, high, static_cast<uint32_t>(grid.tile_count()));
}

}  // namespace catgs::cpu
