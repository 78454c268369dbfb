// Stage 5: tile rasterization, front-to-back (mirrors the CUDA one-block-per-tile kernel, where a
// thread is a pixel; here a task is a tile).
#include <algorithm>

#include "blend_tile.h"
#include "cpu/host_buffer.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

void rasterize(const ProjectedGaussians& projected, const RenderList& list, const TileRanges& ranges,
               const TileGrid& grid, glm::vec3 background, Image& out, std::uint32_t first_tile,
               std::uint32_t end_tile) {
  out.width = grid.width;
  out.height = grid.height;
  const std::size_t pixels = static_cast<std::size_t>(grid.width) * grid.height;
  grow_host(out.rgb, pixels * 3, "RGB image");
  grow_host(out.rgba8, pixels * 4, "RGBA8 image");

  const std::size_t first = first_tile, end = std::min<std::size_t>(grid.tile_count(), end_tile);
  parallel_for(end > first ? end - first : 0, 1, [&](std::size_t k) {
    const std::size_t tile = first + k;
    const int tx = static_cast<int>(tile) % grid.tiles_x, ty = static_cast<int>(tile) / grid.tiles_x;
    glm::vec3 C[kTilePixels] = {};
    float T[kTilePixels];
    std::fill(T, T + kTilePixels, 1.0f);
    blend_tile(projected, list, ranges[tile].x, ranges[tile].y, tx, ty, grid, true, C, T);
    for (int py = ty * fm::kTileSize; py < std::min((ty + 1) * fm::kTileSize, grid.height); ++py) {
      for (int px = tx * fm::kTileSize; px < std::min((tx + 1) * fm::kTileSize, grid.width); ++px) {
        const int l = (py - ty * fm::kTileSize) * fm::kTileSize + (px - tx * fm::kTileSize);
        const glm::vec3 c = C[l] + T[l] * background;
        const std::size_t p = static_cast<std::size_t>(py) * grid.width + px;
        for (int ch = 0; ch < 3; ++ch) {
          out.rgb[3 * p + ch] = c[ch];
          out.rgba8[4 * p + ch] = to_unorm8(c[ch]);
        }
        out.rgba8[4 * p + 3] = 255;
      }
    }
  });
}

}  // namespace catgs::cpu
