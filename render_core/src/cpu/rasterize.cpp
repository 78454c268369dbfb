// Stage 5: tile rasterization, front-to-back (mirrors the CUDA one-block-per-tile kernel, where a
// thread is a pixel; here a task is a tile).
#include "catgs/cpu_renderer.h"

namespace catgs::cpu {

void rasterize(const ProjectedGaussians& projected, const RenderList& list,
               const TileRanges& ranges, const TileGrid& grid, glm::vec3 background, Image& out) {
  out.width = grid.width;
  out.height = grid.height;
  const std::size_t pixels = static_cast<std::size_t>(grid.width) * grid.height;
  out.rgb.resize(pixels * 3);
  out.rgba8.resize(pixels * 4);

  parallel_for(static_cast<std::size_t>(grid.tile_count()), 1, [&](std::size_t tile) {
    const int tx = static_cast<int>(tile) % grid.tiles_x, ty = static_cast<int>(tile) / grid.tiles_x;
    const glm::uvec2 range = ranges[tile];
    for (int py = ty * fm::kTileSize; py < std::min((ty + 1) * fm::kTileSize, grid.height); ++py) {
      for (int px = tx * fm::kTileSize; px < std::min((tx + 1) * fm::kTileSize, grid.width); ++px) {
        float T = 1.0f;
        glm::vec3 C(0.0f);
        for (uint32_t k = range.x; k < range.y; ++k) {
          const uint32_t g = list.values[k];
          const glm::vec2 d = projected.mean2d[g] - glm::vec2(static_cast<float>(px), static_cast<float>(py));
          const float power = fm::gaussian_power(projected.conic[g], d.x, d.y);
          if (power > 0.0f) continue;
          const float alpha = std::min(fm::kMaxAlpha, projected.opacity[g] * std::exp(power));
          if (alpha < fm::kMinAlpha) continue;
          const float test_T = T * (1.0f - alpha);
          if (test_T < fm::kMinTransmittance) break;
          C += projected.color[g] * (alpha * T);
          T = test_T;
        }
        C += T * background;
        const std::size_t p = static_cast<std::size_t>(py) * grid.width + px;
        out.rgb[3 * p] = C.r;
        out.rgb[3 * p + 1] = C.g;
        out.rgb[3 * p + 2] = C.b;
        out.rgba8[4 * p] = to_unorm8(C.r);
        out.rgba8[4 * p + 1] = to_unorm8(C.g);
        out.rgba8[4 * p + 2] = to_unorm8(C.b);
        out.rgba8[4 * p + 3] = 255;
      }
    }
  });
}

}  // namespace catgs::cpu
