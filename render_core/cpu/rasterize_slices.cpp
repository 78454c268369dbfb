// Stage 5 with task splitting (paper sec. 3.4): each slice blends its part of a tile's list into a
// partial colour C_k and transmittance T_k per pixel; the merge composes them front to back.
// Mirrors the GPU's one-block-per-slice kernel and merge kernel, including where a pixel's
// composition ends with early termination: after the first slice in which the pixel stopped
// (T_k stored negated) or after which prod T < 1e-4. The GPU skips the pixels and slices past
// that end when it can; here every slice runs in full and the merge drops them, which gives the
// same image.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "blend_tile.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

void rasterize_slices(const ProjectedGaussians& projected, const RenderList& list, const std::vector<TileSlice>& slices,
                      const TileGrid& grid, bool early_termination, glm::vec3 background, Image& out, double* merge_ms,
                      std::uint32_t first_tile, std::uint32_t end_tile) {
  out.width = grid.width;
  out.height = grid.height;
  const std::size_t pixels = static_cast<std::size_t>(grid.width) * grid.height;
  out.rgb.resize(pixels * 3);
  out.rgba8.resize(pixels * 4);
  // Partial results: [slices, 16 * 16] colour and transmittance.
  std::vector<glm::vec3> partial_color(slices.size() * kTilePixels);
  std::vector<float> partial_T(slices.size() * kTilePixels);

  parallel_for(slices.size(), 1, [&](std::size_t s) {
    const TileSlice& slice = slices[s];
    const int tx = static_cast<int>(slice.tile) % grid.tiles_x, ty = static_cast<int>(slice.tile) / grid.tiles_x;
    glm::vec3* C = &partial_color[s * kTilePixels];
    float* T = &partial_T[s * kTilePixels];
    std::fill(C, C + kTilePixels, glm::vec3(0.0f));
    std::fill(T, T + kTilePixels, 1.0f);
    bool stopped[kTilePixels] = {};
    blend_tile(projected, list, slice.begin, slice.end, tx, ty, grid, early_termination, C, T, stopped);
    for (int p = 0; p < kTilePixels; ++p)
      if (stopped[p]) T[p] = -T[p];
  });

  const auto t0 = std::chrono::steady_clock::now();
  // Merge: slices of a tile are consecutive and in list order.
  std::vector<std::size_t> first_slice(static_cast<std::size_t>(grid.tile_count()) + 1, slices.size());
  for (std::size_t s = slices.size(); s-- > 0;) first_slice[slices[s].tile] = s;
  for (std::size_t t = static_cast<std::size_t>(grid.tile_count()); t-- > 0;)
    if (first_slice[t] == slices.size()) first_slice[t] = first_slice[t + 1];
  // Only this pass's tiles: the image keeps the other passes' (renderer/render_passes.h).
  const std::size_t first = first_tile, end = std::min<std::size_t>(grid.tile_count(), end_tile);
  parallel_for(end > first ? end - first : 0, 1, [&](std::size_t k) {
    const std::size_t tile = first + k;
    const int tx = static_cast<int>(tile) % grid.tiles_x, ty = static_cast<int>(tile) / grid.tiles_x;
    for (int ly = 0; ly < fm::kTileSize; ++ly) {
      const int py = ty * fm::kTileSize + ly;
      if (py >= grid.height) break;
      for (int lx = 0; lx < fm::kTileSize; ++lx) {
        const int px = tx * fm::kTileSize + lx;
        if (px >= grid.width) break;
        glm::vec3 C(0.0f);
        float T = 1.0f;
        for (std::size_t s = first_slice[tile]; s < slices.size() && slices[s].tile == tile; ++s) {
          const std::size_t at = s * kTilePixels + static_cast<std::size_t>(ly * fm::kTileSize + lx);
          C += T * partial_color[at];
          T *= std::fabs(partial_T[at]);
          if (early_termination && (partial_T[at] < 0.0f || T < fm::kMinTransmittance)) break;
        }
        C += T * background;
        const std::size_t p = static_cast<std::size_t>(py) * grid.width + px;
        for (int c = 0; c < 3; ++c) {
          out.rgb[3 * p + c] = C[c];
          out.rgba8[4 * p + c] = to_unorm8(C[c]);
        }
        out.rgba8[4 * p + 3] = 255;
      }
    }
  });
  if (merge_ms) *merge_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace catgs::cpu
