// Occlusion culling's two small stages (forward_model/occlusion.h; mirror cuda/occlusion_map.cu):
// after rasterization, the per-tile map from the rasterizer's opaque points (the frame's entries
// behind them); before pre-processing, the last frame's per-pixel map reprojected onto this frame.
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

fm::OcclusionMap occlusion_reproject(const float* last_pixels, const fm::View& last, const fm::View& now,
                                     std::vector<float>& now_pixels, std::vector<float>& cells) {
  now_pixels.assign(static_cast<std::size_t>(now.width) * now.height, INFINITY);
  // The quads, nearest first at each pixel centre (the GPU: an atomic min per pixel).
  for (int y = 0; y + 1 < last.height; ++y)
    for (int x = 0; x + 1 < last.width; ++x) {
      int i0, i1, j0, j1;
      float z;
      if (!fm::occlusion_quad(last_pixels, last, now, x, y, &i0, &i1, &j0, &j1, &z)) continue;
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) {
          float& d = now_pixels[static_cast<std::size_t>(j) * now.width + i];
          d = std::min(d, z);
        }
    }
  // The cells: level 0 the deepest of its pixels, each later level of its 2 x 2 cells below.
  cells.assign(fm::occlusion_cell_count(now.width, now.height), 0.0f);
  const fm::OcclusionMap m = fm::occlusion_cells(cells.data(), now.width, now.height);
  auto cell = [&](int k, int cx, int cy) -> float& {
    return const_cast<float*>(m.cells[k])[static_cast<std::size_t>(cy) * m.cells_x[k] + cx];
  };
  for (int y = 0; y < now.height; ++y)
    for (int x = 0; x < now.width; ++x) {
      float& c = cell(0, x / fm::kOcclusionCell, y / fm::kOcclusionCell);
      c = std::max(c, now_pixels[static_cast<std::size_t>(y) * now.width + x]);
    }
  for (int k = 1; k < fm::kOcclusionLevels; ++k)
    for (int cy = 0; cy < m.cells_y[k - 1]; ++cy)
      for (int cx = 0; cx < m.cells_x[k - 1]; ++cx) {
        float& c = cell(k, cx / 2, cy / 2);
        c = std::max(c, cell(k - 1, cx, cy));
      }
  return m;
}

}  // namespace catgs::cpu
