// Stage 5b of exact frames with occlusion culling: the occlusion map from the rasterizer's opaque
// points (forward_model/occlusion.h; mirrors cuda/occlusion_map.cu).
#include <algorithm>
#include <cmath>

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

std::uint64_t occlusion_map(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
                            const std::uint32_t* tile_opaque_at, std::uint32_t first_tile, std::uint32_t end_tile,
                            float* tile_depth) {
  std::uint64_t behind = 0;
  const std::uint32_t end = std::min<std::uint32_t>(end_tile, static_cast<std::uint32_t>(ranges.size()));
  for (std::uint32_t t = first_tile; t < end; ++t) {
    const std::uint32_t P = tile_opaque_at[t];
    if (P == UINT32_MAX || P == 0 || P > ranges[t].y) {
      tile_depth[t] = INFINITY;
      continue;
    }
    tile_depth[t] = projected.depth[list.values[P - 1]];
    behind += ranges[t].y - P;
  }
  return behind;
}

}  // namespace catgs::cpu
