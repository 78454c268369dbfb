// Stage 3: sort the render list by [tile | depth] (mirrors CUB's stable radix sort).
#include <algorithm>
#include <numeric>

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

void sort_render_list(RenderList& list) {
  const std::size_t n = list.keys.size();
  // Sorting (key, value) pairs equals a stable sort by key: values are emitted in increasing
  // Gaussian index within a tile, and equal keys only occur within a tile.
  std::vector<std::pair<uint64_t, uint32_t>> pairs(n);
  for (std::size_t i = 0; i < n; ++i) pairs[i] = {list.keys[i], list.values[i]};
  std::sort(pairs.begin(), pairs.end());
  for (std::size_t i = 0; i < n; ++i) {
    list.keys[i] = pairs[i].first;
    list.values[i] = pairs[i].second;
  }
}

}  // namespace catgs::cpu
