#include "blend_tile.h"

#include <cmath>

namespace catgs::cpu {

namespace {
// v (a floor or ceil) as an int within [lo, hi]: a huge or NaN box edge (a Gaussian far off the
// tile, or of absurd size in a hostile file) must not be converted to int out of range, which is
// undefined behaviour (found by tests/fuzz fuzz_scene).
int clamped_int(float v, int lo, int hi) {
  if (!(v > static_cast<float>(lo))) return lo;
  if (!(v < static_cast<float>(hi))) return hi;
  return static_cast<int>(v);
}
}  // namespace

void blend_tile(const ProjectedGaussians& projected, const RenderList& list, uint32_t begin, uint32_t end, int tx,
                int ty, const TileGrid& grid, bool early_termination, glm::vec3* C, float* T, bool* stopped,
                uint32_t* occluded_at, uint8_t* changed) {
  const int x0 = tx * fm::kTileSize, y0 = ty * fm::kTileSize;
  const int x1 = std::min(x0 + fm::kTileSize, grid.width) - 1;
  const int y1 = std::min(y0 + fm::kTileSize, grid.height) - 1;
  bool done[kTilePixels] = {};
  int remaining = (x1 - x0 + 1) * (y1 - y0 + 1);
  for (uint32_t k = begin; k < end && remaining > 0; ++k) {
    const uint32_t g = list.values[k];
    const glm::vec3 con = projected.conic[g];
    const float q_lim = projected.q_max[g] + fm::kExactQMargin;
    const float det = con.x * con.z - con.y * con.y;
    if (!(q_lim > 0.0f) || !(det > 0.0f)) continue;
    // Box of q <= q_lim: half-widths sqrt(q_lim * cov_xx), sqrt(q_lim * cov_yy), cov = conic^-1.
    const glm::vec2 mean = projected.mean2d[g];
    const float hx = std::sqrt(q_lim * con.z / det), hy = std::sqrt(q_lim * con.x / det);
    const int bx0 = clamped_int(std::floor(mean.x - hx), x0, x1 + 1);
    const int bx1 = clamped_int(std::ceil(mean.x + hx), x0 - 1, x1);
    const int by0 = clamped_int(std::floor(mean.y - hy), y0, y1 + 1);
    const int by1 = clamped_int(std::ceil(mean.y + hy), y0 - 1, y1);
    const float opacity = projected.opacity[g];
    const glm::vec3 color = projected.color[g];
    for (int py = by0; py <= by1; ++py) {
      for (int px = bx0; px <= bx1; ++px) {
        const int p = (py - y0) * fm::kTileSize + (px - x0);
        if (done[p]) continue;
        const glm::vec2 d = mean - glm::vec2(static_cast<float>(px), static_cast<float>(py));
        const float power = fm::gaussian_power(con, d.x, d.y);
        if (power > 0.0f) continue;
        const float alpha = std::min(fm::kMaxAlpha, opacity * std::exp(power));
        if (alpha < fm::kMinAlpha) continue;
        const float test_T = T[p] * (1.0f - alpha);
        if (early_termination && test_T < fm::kMinTransmittance) {
          done[p] = true;
          if (stopped) stopped[p] = true;
          if (occluded_at && occluded_at[p] == UINT32_MAX) occluded_at[p] = k;
          --remaining;
          continue;
        }
        if (changed && T[p] > fm::kOcclusionTransmittance) changed[k] = 1;
        C[p] += color * (alpha * T[p]);
        T[p] = test_T;
        if (occluded_at && occluded_at[p] == UINT32_MAX && test_T < fm::kOcclusionTransmittance) occluded_at[p] = k;
      }
    }
  }
}

}  // namespace catgs::cpu
