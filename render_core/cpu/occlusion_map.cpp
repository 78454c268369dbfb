// Occlusion culling's two small stages (forward_model/occlusion.h; mirror cuda/occlusion_map.cu):
// after rasterization, the map from the rasterizer's opaque points; before pre-processing, the
// last frame's map reprojected onto this frame's tiles.
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

void occlusion_reproject(const fm::OcclusionMap& map, const fm::View& now, const TileGrid& grid,
                         std::vector<float>& out) {
  out.resize(static_cast<std::size_t>(grid.tile_count()));
  for (int ty = 0; ty < grid.tiles_y; ++ty)
    for (int tx = 0; tx < grid.tiles_x; ++tx)
      out[static_cast<std::size_t>(ty) * grid.tiles_x + tx] = fm::reprojected_tile_depth(map, now, tx, ty);
}

}  // namespace catgs::cpu
