// Issue 72's measurement of how much of the cut a finer occlusion test could drop before
// pre-processing (CpuRenderer::count_changes): this frame's own opaque depth per pixel (the depth of
// the list entry at which the pixel's transmittance fell below fm::kOcclusionTransmittance or it
// stopped, +inf where neither happened), as a max-depth pyramid (2 x 2 per level), and the cut's
// chunks and Gaussians whose screen boxes lie behind it. It is this frame's own map: a bound on
// what any map (the last frame's, reprojected) can drop.
#include <algorithm>
#include <cmath>

#include "base/parallel_for.h"
#include "blend_tile.h"
#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

namespace {

// Max-depth pyramid: level 0 per pixel, level k per 2^k x 2^k pixels.
struct DepthPyramid {
  std::vector<std::vector<float>> level;
  std::vector<int> w, h;

  explicit DepthPyramid(std::vector<float> base, int width, int height) {
    level.push_back(std::move(base));
    w.push_back(width);
    h.push_back(height);
    while (w.back() > 1 || h.back() > 1) {
      const int pw = w.back(), ph = h.back(), nw = (pw + 1) / 2, nh = (ph + 1) / 2;
      std::vector<float> next(static_cast<std::size_t>(nw) * nh);
      const std::vector<float>& prev = level.back();
      for (int y = 0; y < nh; ++y)
        for (int x = 0; x < nw; ++x) {
          float d = 0.0f;
          for (int k = 0; k < 4; ++k) {
            const int sx = std::min(2 * x + (k & 1), pw - 1), sy = std::min(2 * y + (k >> 1), ph - 1);
            d = std::max(d, prev[static_cast<std::size_t>(sy) * pw + sx]);
          }
          next[static_cast<std::size_t>(y) * nw + x] = d;
        }
      level.push_back(std::move(next));
      w.push_back(nw);
      h.push_back(nh);
    }
  }

  // The largest depth over pixels [x0, x1] x [y0, y1] (clamped to the image), read at the finest
  // level (>= min_level) where the box spans at most 4 x 4 cells; -1 for a box off the image.
  float deepest(float fx0, float fx1, float fy0, float fy1, int min_level) const {
    const float W = static_cast<float>(w[0] - 1), H = static_cast<float>(h[0] - 1);
    if (!(fx1 >= 0.0f && fy1 >= 0.0f && fx0 <= W && fy0 <= H)) return -1.0f;
    const int x0 = static_cast<int>(std::max(0.0f, std::floor(fx0))),
              x1 = static_cast<int>(std::min(W, std::ceil(fx1)));
    const int y0 = static_cast<int>(std::max(0.0f, std::floor(fy0))),
              y1 = static_cast<int>(std::min(H, std::ceil(fy1)));
    int k = min_level;
    while (k + 1 < static_cast<int>(level.size()) && ((x1 >> k) - (x0 >> k) > 3 || (y1 >> k) - (y0 >> k) > 3)) ++k;
    float d = 0.0f;
    for (int y = y0 >> k; y <= (y1 >> k); ++y)
      for (int x = x0 >> k; x <= (x1 >> k); ++x) d = std::max(d, level[k][static_cast<std::size_t>(y) * w[k] + x]);
    return d;
  }
};

// This frame's opaque depth per pixel: every tile's list blended again, one slice a tile.
std::vector<float> opaque_depth_per_pixel(const ProjectedGaussians& projected, const RenderList& list,
                                          const TileRanges& ranges, const TileGrid& grid) {
  std::vector<float> depth(static_cast<std::size_t>(grid.width) * grid.height, INFINITY);
  parallel_for(static_cast<std::size_t>(grid.tile_count()), 1, [&](std::size_t t) {
    const int tx = static_cast<int>(t) % grid.tiles_x, ty = static_cast<int>(t) / grid.tiles_x;
    glm::vec3 C[kTilePixels] = {};
    float T[kTilePixels];
    std::fill(T, T + kTilePixels, 1.0f);
    uint32_t at[kTilePixels];
    std::fill(at, at + kTilePixels, UINT32_MAX);
    blend_tile(projected, list, ranges[t].x, ranges[t].y, tx, ty, grid, true, C, T, nullptr, at, nullptr);
    for (int p = 0; p < kTilePixels; ++p) {
      const int px = tx * fm::kTileSize + p % fm::kTileSize, py = ty * fm::kTileSize + p / fm::kTileSize;
      if (px < grid.width && py < grid.height && at[p] != UINT32_MAX) {
        // The pixel's own P - 1: its crossing's round's end (what the rasterizers write).
        const uint32_t b = ranges[t].x;
        const uint32_t k =
            std::min<uint32_t>(ranges[t].y, b + ((at[p] - b) / fm::kOcclusionRound + 1) * fm::kOcclusionRound) - 1;
        depth[static_cast<std::size_t>(py) * grid.width + px] = projected.depth[list.values[k]];
      }
    }
  });
  return depth;
}

// Whether bound b's screen box (its means' box widened by its largest ellipse, as fm::chunk_hidden)
// lies behind the pyramid, in front of its nearest mean.
bool box_hidden(const DepthPyramid& pyramid, const fm::ChunkBounds& b, const fm::View& view) {
  const fm::ChunkOnScreen s = fm::chunk_on_screen(b, view);
  if (s.kind != fm::ChunkOnScreen::box) return false;
  const float r = fm::chunk_half_extent(b, view, s.z_lo) + fm::chunk_rounding_slack(s);
  const float fine = pyramid.deepest(s.u_lo - r, s.u_hi + r, s.w_lo - r, s.w_hi + r, 0);
  return fine >= 0.0f && fine < s.z_lo * (1.0f - 1e-5f);
}

constexpr std::size_t kGroupGaussians = 32;

}  // namespace

void count_hidden(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                  float lod_error_px, const ProjectedGaussians& projected, const RenderList& list,
                  const TileRanges& ranges, FrameStats& stats) {
  const TileGrid grid = TileGrid::of(camera.width, camera.height);
  const DepthPyramid pyramid(opaque_depth_per_pixel(projected, list, ranges, grid), grid.width, grid.height);
  const fm::View view = fm::view_of(camera);
  const fm::LodCut cut = fm::lod_cut(model.lod, view, lod_error_px);
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    if (!cut.drawn(c) || fm::chunk_outside_view(chunks[c], view)) continue;
    const std::size_t begin = c * fm::kChunkSize, end = std::min(model.size(), begin + fm::kChunkSize);
    stats.gaussians_preprocessed += end - begin;
    if (box_hidden(pyramid, chunks[c], view)) stats.gaussians_in_hidden_chunks += end - begin;
    // The same test per run of kGroupGaussians (a warp's share of the chunk), with the run's own
    // bound: what a bound per warp would add.
    for (std::size_t g = begin; g < end; g += kGroupGaussians) {
      const std::size_t n = std::min(end - g, kGroupGaussians);
      const fm::ChunkBounds b =
          fm::run_bound(model.means.data(), model.log_scales.data(), model.opacity_logits.data(), g, g + n);
      if (box_hidden(pyramid, b, view)) stats.gaussians_in_hidden_groups += n;
    }
    for (std::size_t i = begin; i < end; ++i) {
      if (projected.tiles_touched[i] == 0) continue;
      const glm::vec3 con = projected.conic[i];
      const float det = con.x * con.z - con.y * con.y, q = projected.q_max[i] + fm::kExactQMargin;
      if (!(det > 0.0f && q > 0.0f)) continue;
      const float hx = std::sqrt(q * con.z / det), hy = std::sqrt(q * con.x / det);
      const glm::vec2 m = projected.mean2d[i];
      const float d = pyramid.deepest(m.x - hx, m.x + hx, m.y - hy, m.y + hy, 0);
      const float z = projected.depth[i] * (1.0f - 1e-5f);
      if (d >= 0.0f && d < z) ++stats.gaussians_hidden_alone;
      // Per entry: the Gaussian's box within each tile it is listed in, against the pixels.
      const fm::TileRect& rect = projected.tile_rect[i];
      for (int ty = rect.y0; ty < rect.y1; ++ty)
        for (int tx = rect.x0; tx < rect.x1; ++tx) {
          if (!fm::ellipse_touches_tile(m, con, projected.q_max[i], tx, ty, camera.width, camera.height)) continue;
          const float bx0 = std::max(m.x - hx, static_cast<float>(tx * fm::kTileSize));
          const float bx1 = std::min(m.x + hx, static_cast<float>(tx * fm::kTileSize + fm::kTileSize - 1));
          const float by0 = std::max(m.y - hy, static_cast<float>(ty * fm::kTileSize));
          const float by1 = std::min(m.y + hy, static_cast<float>(ty * fm::kTileSize + fm::kTileSize - 1));
          const float e = pyramid.deepest(bx0, bx1, by0, by1, 0);
          if (e >= 0.0f && e < z) ++stats.entries_hidden_pixels;
        }
    }
  }
}

}  // namespace catgs::cpu
