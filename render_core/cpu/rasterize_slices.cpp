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
#include "cpu/host_buffer.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

void rasterize_slices(const ProjectedGaussians& projected, const RenderList& list, const std::vector<TileSlice>& slices,
                      const TileGrid& grid, bool early_termination, glm::vec3 background, Image& out, double* merge_ms,
                      std::uint32_t first_tile, std::uint32_t end_tile, std::uint32_t* tile_opaque_at,
                      std::uint8_t* changed, float* pixel_depth) {
  out.width = grid.width;
  out.height = grid.height;
  const std::size_t pixels = static_cast<std::size_t>(grid.width) * grid.height;
  grow_host(out.rgb, pixels * 3, "RGB image");
  grow_host(out.rgba8, pixels * 4, "RGBA8 image");
  // Partial results: [slices, 16 * 16] colour and transmittance.
  std::vector<glm::vec3> partial_color(slices.size() * kTilePixels);
  std::vector<float> partial_T(slices.size() * kTilePixels);
  // Per slice and pixel: the list position at which it stopped or its T fell below
  // fm::kOcclusionTransmittance (the occlusion map).
  std::vector<uint32_t> stop_at(tile_opaque_at ? slices.size() * kTilePixels : 0, UINT32_MAX);

  parallel_for(slices.size(), 1, [&](std::size_t s) {
    const TileSlice& slice = slices[s];
    const int tx = static_cast<int>(slice.tile) % grid.tiles_x, ty = static_cast<int>(slice.tile) / grid.tiles_x;
    glm::vec3* C = &partial_color[s * kTilePixels];
    float* T = &partial_T[s * kTilePixels];
    std::fill(C, C + kTilePixels, glm::vec3(0.0f));
    std::fill(T, T + kTilePixels, 1.0f);
    bool stopped[kTilePixels] = {};
    blend_tile(projected, list, slice.begin, slice.end, tx, ty, grid, early_termination, C, T, stopped,
               tile_opaque_at ? &stop_at[s * kTilePixels] : nullptr, changed);
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
    // The occlusion map's P (forward_model/occlusion.h): past every pixel's occluding position, 0
    // while none is known, UINT32_MAX once a pixel has none.
    uint32_t saturated_at = 0;
    for (int ly = 0; ly < fm::kTileSize; ++ly) {
      const int py = ty * fm::kTileSize + ly;
      if (py >= grid.height) break;
      for (int lx = 0; lx < fm::kTileSize; ++lx) {
        const int px = tx * fm::kTileSize + lx;
        if (px >= grid.width) break;
        glm::vec3 C(0.0f);
        float T = 1.0f;
        uint32_t ended_at = UINT32_MAX;
        for (std::size_t s = first_slice[tile]; s < slices.size() && slices[s].tile == tile; ++s) {
          const std::size_t at = s * kTilePixels + static_cast<std::size_t>(ly * fm::kTileSize + lx);
          C += T * partial_color[at];
          T *= std::fabs(partial_T[at]);
          // The first slice that makes the pixel opaque: where its own walk crossed, taken to the
          // end of the GPU's round of fm::kOcclusionRound entries from the slice's start; else,
          // opaque only with the slices before it, the slice's end (as the GPU's merge).
          if (tile_opaque_at && ended_at == UINT32_MAX) {
            if (stop_at[at] != UINT32_MAX)
              ended_at = std::min(slices[s].end,
                                  slices[s].begin +
                                      (stop_at[at] - slices[s].begin) / fm::kOcclusionRound * fm::kOcclusionRound +
                                      fm::kOcclusionRound);
            else if (partial_T[at] < 0.0f || T < fm::kOcclusionTransmittance)
              ended_at = slices[s].end;
          }
          if (early_termination && (partial_T[at] < 0.0f || T < fm::kMinTransmittance)) break;
        }
        saturated_at = std::max(saturated_at, ended_at);
        C += T * background;
        const std::size_t p = static_cast<std::size_t>(py) * grid.width + px;
        if (pixel_depth)
          pixel_depth[p] = ended_at == UINT32_MAX ? INFINITY : projected.depth[list.values[ended_at - 1]];
        for (int c = 0; c < 3; ++c) {
          out.rgb[3 * p + c] = C[c];
          out.rgba8[4 * p + c] = to_unorm8(C[c]);
        }
        out.rgba8[4 * p + 3] = 255;
      }
    }
    if (tile_opaque_at) tile_opaque_at[tile] = saturated_at == 0 ? UINT32_MAX : saturated_at;
  });
  if (merge_ms) *merge_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace catgs::cpu
