// Stage 5b: the frame's depth grid (forward_model/depth_grid.h; mirrors cuda/depth_grid.cu): each
// vertex's pixel walks its tile's sorted range front to back until its transmittance falls to
// 0.5. A task is a row of vertices.
#include <algorithm>
#include <cmath>

#include "base/parallel_for.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/depth_grid.h"

namespace catgs::cpu {

void depth_grid(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
                const TileGrid& grid, int cell, std::uint32_t first_tile, std::uint32_t end_tile, DepthGrid& out) {
  const int cols = fm::depth_grid_cols(grid.width, cell), rows = fm::depth_grid_rows(grid.height, cell);
  if (out.cols != cols || out.rows != rows || out.cell != cell) {
    out.cols = cols;
    out.rows = rows;
    out.cell = cell;
    out.depth.assign(static_cast<std::size_t>(cols) * rows, INFINITY);
  }
  parallel_for(static_cast<std::size_t>(rows), 1, [&](std::size_t l) {
    const int py = fm::depth_grid_pixel(static_cast<int>(l), cell, grid.height);
    for (int k = 0; k < cols; ++k) {
      const int px = fm::depth_grid_pixel(k, cell, grid.width);
      const auto tile = static_cast<std::uint32_t>((py / fm::kTileSize) * grid.tiles_x + px / fm::kTileSize);
      if (tile < first_tile || tile >= end_tile) continue;  // another pass's tile
      fm::MedianDepthWalk walk;
      for (std::uint32_t e = ranges[tile].x; e < ranges[tile].y; ++e) {
        const std::uint32_t g = list.values[e];
        if (walk.step(projected.mean2d[g], projected.conic[g], projected.opacity[g], projected.depth[g],
                      static_cast<float>(px), static_cast<float>(py)))
          break;
      }
      out.depth[l * static_cast<std::size_t>(cols) + static_cast<std::size_t>(k)] = walk.depth;
    }
  });
}

}  // namespace catgs::cpu
