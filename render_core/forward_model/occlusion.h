// Occlusion culling from the session's last frame (issue 72): a render-list entry that lay behind
// where the last frame's tile became opaque is not listed, sorted or blended this frame.
//
// The occlusion map of a frame (written by the exact pipeline's rasterizer, both cores:
// cpu/rasterize_slices.cpp, cuda/rasterize_slices.cu): per 16 x 16 tile of that frame's grid, the
// view depth (camera-space z of the mean, the sort's depth) of the entry at list position P - 1,
// where by position P every pixel of the tile had stopped (early termination) or had
// transmittance T below kOcclusionTransmittance = 1/255. Entries at positions >= P then change a
// pixel by at most its remaining T times their colour, in all under 1/255: under one 8-bit level
// (the "changes any pixel" criterion). +inf (the GPU: the largest finite float) where
// some pixel never got there (it saw the background through the tile's Gaussians). P is
// - a tile drawn as one slice: the end of the rasterizer's round of kOcclusionRound entries
//   (counted from the tile's start, as the GPU walks them) in which its last pixel got there;
// - a split tile (task splitting), per pixel as the merge composes it: in the first slice that
//   makes it opaque, the end of the round where its own walk crossed, else (opaque only with the
//   slices before) that slice's end; the tile's P is the largest.
// Both cores compute P the same way from the same list; alpha's few-ulp rounding can move a
// pixel's crossing by an entry, and so P by a round, where it falls on a round's edge.
//
// The rasterizer also writes the map per pixel: the view depth of the entry at the pixel's own P
// - 1 (its round's end, as above), +inf (the GPU: the largest finite float) where it has none.
//
// The next frame reads the per-pixel map in two steps (both cores):
// - forward reprojection (occlusion_quad, occlusion_cells), a small stage before pre-processing:
//   each 2 x 2 block of neighbouring pixels of the last frame whose four depths are all finite is a
//   quad between their opaque points (pixel centre rays at those depths), drawn into this frame
//   at the deepest of its four corners' new view depths, with a depth test (the nearest quad wins
//   a pixel centre, as surfaces occlude). A pixel no quad covers has no data (+inf): what the last
//   frame did not see (a disocclusion, the image's new edge, a gap torn between two depths) is
//   drawn. Then per cell of 4 x 4, 8 x 8 and 16 x 16 pixels the deepest of its pixels;
// - per entry (entry_hidden): a small Gaussian's entry in a tile is dropped when its view depth
//   lies behind (1e-3 deeper: the 32-bit sort key joins depths within 3.1e-5) the deepest cell
//   over its q_max ellipse's pixel box within that tile (read at the finest level where the box
//   spans at most 2 x 2 cells). A Gaussian over more than 32 tiles keeps them all (the CUDA core
//   counts and emits those from the ellipse alone) unless its chunk goes whole (chunk_hidden); a
//   small Gaussian all of whose entries are dropped skips its SH colour.
// With the same pose each quad covers exactly the pixel centres it was drawn from, so a dropped
// entry lies behind its pixels' opaque points: the picture differs from the unculled one by under
// 1/255 a pixel. A moving eye moves each quad by its own parallax; a quad spans the last frame's
// surface between its four opaque points, so where the surface has a hole smaller than a pixel
// that the new pose looks through, an entry may be dropped that shows (the benchmark measures it:
// catgs-bench exact-occlusion against exact on the same frames, both against the 4x supersampled
// render). A dropped entry that should have shown leaves its pixels less opaque in this frame's own
// map, so the next frame draws it. (The first form, one depth per tile read back through a box
// widened by the parallax of its nearest occluder, dropped far fewer: docs/history/occlusion_culling.md.)
#pragma once

#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"

namespace catgs::fm {

inline constexpr float kOcclusionDepthSlack = 1.0f + 1e-3f;      // the sort key's depth ties, with room
inline constexpr float kOcclusionTransmittance = 1.0f / 255.0f;  // a pixel is opaque below it
inline constexpr uint32_t kOcclusionRound = 256;   // entries a GPU rasterizer round stages (tune::kRasterBatch)
inline constexpr int kOcclusionLevels = 3;         // cells of 4, 8 and 16 pixels a side
inline constexpr int kOcclusionCell = 4;           // the finest cell's side, pixels
inline constexpr float kOcclusionQuadMax = 64.0f;  // a quad wider or taller (pixels) is not drawn

// The cells' extent at level k of a width x height frame.
CATGS_HD int occlusion_cells_x(int width, int k) { return (width + (kOcclusionCell << k) - 1) / (kOcclusionCell << k); }
CATGS_HD int occlusion_cells_y(int height, int k) {
  return (height + (kOcclusionCell << k) - 1) / (kOcclusionCell << k);
}

// The last frame's map as this frame's pre-processing reads it. cells[0] null: no map (the first
// frame, a new scene or options): nothing is culled.
struct OcclusionMap {
  const float* cells[kOcclusionLevels] = {};  // per level, row-major, this frame's view depth (+inf: no data)
  int cells_x[kOcclusionLevels] = {}, cells_y[kOcclusionLevels] = {};
};

// The map's levels over buffer `cells` (kOcclusionLevels runs, level k occlusion_cells_x(width, k)
// x occlusion_cells_y(height, k) floats, one after another) of a width x height frame; null: none.
inline OcclusionMap occlusion_cells(const float* cells, int width, int height) {
  OcclusionMap m;
  if (cells == nullptr) return m;
  for (int k = 0; k < kOcclusionLevels; ++k) {
    m.cells[k] = cells;
    m.cells_x[k] = occlusion_cells_x(width, k);
    m.cells_y[k] = occlusion_cells_y(height, k);
    cells += static_cast<std::size_t>(m.cells_x[k]) * m.cells_y[k];
  }
  return m;
}
inline std::size_t occlusion_cell_count(int width, int height) {
  std::size_t n = 0;
  for (int k = 0; k < kOcclusionLevels; ++k)
    n += static_cast<std::size_t>(occlusion_cells_x(width, k)) * occlusion_cells_y(height, k);
  return n;
}

// The quad of last frame's pixels (x, y) .. (x + 1, y + 1) (`depth`: last's per-pixel map) drawn
// into `now`: the pixel centres [*i0, *i1] x [*j0, *j1] of now it covers (pixel i's centre at i,
// clamped to the image; empty when i0 > i1) and its depth *z, the deepest of its corners' view
// depths in now. False where it draws nothing: a corner without depth, one at or behind now's
// eye, or a quad over kOcclusionQuadMax pixels across.
CATGS_HD bool occlusion_quad(const float* depth, const View& last, const View& now, int x, int y, int* i0, int* i1,
                             int* j0, int* j1, float* z) {
  const glm::mat3 to_now = now.R * glm::transpose(last.R);
  const glm::vec3 t_now = now.t - to_now * last.t;
  float u0 = INFINITY, u1 = -INFINITY, w0 = INFINITY, w1 = -INFINITY, deepest = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const int px = x + (k & 1), py = y + (k >> 1);
    const float d = depth[py * last.width + px];
    if (!(d < 3.0e38f)) return false;  // +inf, the GPU's largest finite float, or NaN
    const glm::vec3 p((static_cast<float>(px) + 0.5f - last.cx) / last.fx * d,
                      (static_cast<float>(py) + 0.5f - last.cy) / last.fy * d, d);
    const glm::vec3 q = to_now * p + t_now;
    if (!(q.z > 1e-4f)) return false;
    const float u = now.fx * q.x / q.z + now.cx - 0.5f, w = now.fy * q.y / q.z + now.cy - 0.5f;
    u0 = fminf(u0, u), u1 = fmaxf(u1, u), w0 = fminf(w0, w), w1 = fmaxf(w1, w);
    deepest = fmaxf(deepest, q.z);
  }
  if (!(u1 - u0 <= kOcclusionQuadMax && w1 - w0 <= kOcclusionQuadMax)) return false;
  // Clamped as floats first: a quad off the image may not fit an int.
  *i0 = static_cast<int>(ceilf(fmaxf(u0, 0.0f)));
  *i1 = static_cast<int>(floorf(fminf(u1, static_cast<float>(now.width - 1))));
  *j0 = static_cast<int>(ceilf(fmaxf(w0, 0.0f)));
  *j1 = static_cast<int>(floorf(fminf(w1, static_cast<float>(now.height - 1))));
  *z = deepest;
  return *i0 <= *i1 && *j0 <= *j1;
}

// The deepest map depth over pixels [x0, x1] x [y0, y1] of this frame (x0 <= x1, y0 <= y1, within
// the image), read at the finest level where the box spans at most 2 x 2 cells. The level's
// array is picked by branches, not indexed by k: a runtime index into the map's arrays would put
// the kernel parameter in local memory (the GPU's pre-processing profile showed its loads).
static_assert(kOcclusionLevels == 3, "occlusion_box_depth picks one of three levels");
CATGS_HD float occlusion_box_depth(const OcclusionMap& m, int x0, int x1, int y0, int y1) {
  int k = 0, s = 2;  // s: log2 of level k's cell side
  while (k + 1 < kOcclusionLevels && ((x1 >> s) - (x0 >> s) > 1 || (y1 >> s) - (y0 >> s) > 1)) ++k, ++s;
  const float* cells = k == 0 ? m.cells[0] : k == 1 ? m.cells[1] : m.cells[2];
  const int cells_x = k == 0 ? m.cells_x[0] : k == 1 ? m.cells_x[1] : m.cells_x[2];
  const int cx0 = x0 >> s, cx1 = x1 >> s, cy0 = y0 >> s, cy1 = y1 >> s;
  float deepest = 0.0f;
  // At most 2 x 2 cells: four reads, no loop (a cell is read twice where the box spans one).
  if (cx1 - cx0 <= 1 && cy1 - cy0 <= 1) {
    const float* row0 = cells + cy0 * cells_x;
    const float* row1 = cells + cy1 * cells_x;
    return fmaxf(fmaxf(fmaxf(deepest, row0[cx0]), fmaxf(row0[cx1], row1[cx0])), row1[cx1]);
  }
  for (int cy = cy0; cy <= cy1; ++cy)  // the coarsest level under a larger box
    for (int cx = cx0; cx <= cx1; ++cx) deepest = fmaxf(deepest, cells[cy * cells_x + cx]);
  return deepest;
}

// Per-entry culling: a small Gaussian's (rect of at most kOcclusionEntryTiles tiles) entry in tile
// (tx, ty) of a width x height frame is hidden when its view depth lies behind the map's deepest
// over its ellipse's pixel box (q <= q_max + kExactQMargin, as the rasterizer visits) within the
// tile. A Gaussian over more tiles keeps them all (the CUDA core counts and emits those with a
// warp, from the ellipse alone), unless chunk_hidden drops its chunk whole.
inline constexpr int kOcclusionEntryTiles = 32;  // the CUDA core's tune::kBigRectTiles (static_assert there)

// The half-widths (pixels) of the box of the ellipse q <= q_max + kExactQMargin from its conic,
// sqrt(q cov_xx) and sqrt(q cov_yy) with cov = conic^-1: entry_hidden's box, worked out once per
// Gaussian where its tiles are tested in a loop. False (nothing hidden) for a degenerate conic.
CATGS_HD bool entry_half_widths(glm::vec3 conic, float q_max, glm::vec2* half) {
  const float det = conic.x * conic.z - conic.y * conic.y, q = q_max + kExactQMargin;
  if (!(det > 0.0f && q > 0.0f)) return false;
  *half = glm::vec2(sqrtf(q * conic.z / det), sqrtf(q * conic.x / det));
  return true;
}
// entry_hidden with the half-widths given (entry_half_widths).
CATGS_HD bool entry_box_hidden(const OcclusionMap& m, glm::vec2 mean2d, glm::vec2 half, float depth, int tx, int ty,
                               int width, int height) {
  const float tx0 = static_cast<float>(tx * kTileSize), ty0 = static_cast<float>(ty * kTileSize);
  const float tx1 = fminf(tx0 + (kTileSize - 1), static_cast<float>(width - 1));
  const float ty1 = fminf(ty0 + (kTileSize - 1), static_cast<float>(height - 1));
  const float x0 = fmaxf(floorf(mean2d.x - half.x), tx0), x1 = fminf(ceilf(mean2d.x + half.x), tx1);
  const float y0 = fmaxf(floorf(mean2d.y - half.y), ty0), y1 = fminf(ceilf(mean2d.y + half.y), ty1);
  if (!(x0 <= x1 && y0 <= y1)) return false;
  const float d =
      occlusion_box_depth(m, static_cast<int>(x0), static_cast<int>(x1), static_cast<int>(y0), static_cast<int>(y1));
  return d * kOcclusionDepthSlack < depth;
}
CATGS_HD bool entry_hidden(const OcclusionMap& m, glm::vec2 mean2d, glm::vec3 conic, float q_max, float depth, int tx,
                           int ty, int width, int height) {
  glm::vec2 half;
  return entry_half_widths(conic, q_max, &half) && entry_box_hidden(m, mean2d, half, depth, tx, ty, width, height);
}

// Chunk culling by the map, before any per-Gaussian work (the cull stage: cpu/preprocess.cpp's
// chunk loop, cuda/preprocess.cu cull_chunks_kernel): chunk `b` is hidden whole in view v when its
// box of means lies in front of the near plane and the map's deepest over a pixel box that holds
// every ellipse of its Gaussians lies in front of its nearest corner. That box is the means' pixel
// box (chunk_on_screen) widened by the ellipse bound at q_max + kExactQMargin (chunk_half_extent)
// and chunk_outside_view's rounding slack; every mean lies
// no nearer than that corner (z is linear over the box; 1e-5 of the terms of z covers its
// rounding, as chunk_means_off_image allows). So every entry of
// each of its Gaussians, small or big, lies behind the deepest over its own box (a sub-box, read
// no nearer): what entry_hidden guarantees for an entry it drops. Tested only where the box spans
// at most kOcclusionChunkCells cells of the coarsest level a side (a chunk near the eye, which
// the map seldom hides whole, reads no more than that).
inline constexpr int kOcclusionChunkCells = 12;
CATGS_HD bool chunk_hidden(const OcclusionMap& m, const ChunkBounds& b, const View& v) {
  if (m.cells[0] == nullptr) return false;
  const ChunkOnScreen s = chunk_on_screen(b, v);
  if (s.kind != ChunkOnScreen::box) return false;
  ChunkBounds with_margin = b;
  with_margin.q_max = fmaxf(b.q_max, 0.0f) + kExactQMargin;
  const glm::vec2 r = chunk_half_extents(with_margin, s, v) + chunk_rounding_slack(s);
  if (!(r.x < 1e7f && r.y < 1e7f && fabsf(s.u_lo) < 1e7f && fabsf(s.u_hi) < 1e7f && fabsf(s.w_lo) < 1e7f &&
        fabsf(s.w_hi) < 1e7f))
    return false;
  const float x0 = fmaxf(floorf(s.u_lo - r.x), 0.0f), x1 = fminf(ceilf(s.u_hi + r.x), static_cast<float>(v.width - 1));
  const float y0 = fmaxf(floorf(s.w_lo - r.y), 0.0f), y1 = fminf(ceilf(s.w_hi + r.y), static_cast<float>(v.height - 1));
  if (!(x0 <= x1 && y0 <= y1)) return false;  // off the image: chunk_outside_view culls it
  const int coarsest = kOcclusionCell << (kOcclusionLevels - 1);
  if (static_cast<int>(x1) / coarsest - static_cast<int>(x0) / coarsest >= kOcclusionChunkCells ||
      static_cast<int>(y1) / coarsest - static_cast<int>(y0) / coarsest >= kOcclusionChunkCells)
    return false;
  const float d =
      occlusion_box_depth(m, static_cast<int>(x0), static_cast<int>(x1), static_cast<int>(y0), static_cast<int>(y1));
  const float terms = fmaxf(fabsf(b.lo.x), fabsf(b.hi.x)) + fmaxf(fabsf(b.lo.y), fabsf(b.hi.y)) +
                      fmaxf(fabsf(b.lo.z), fabsf(b.hi.z)) + fabsf(v.t.z) + fabsf(s.z_lo);
  return d * kOcclusionDepthSlack < s.z_lo - 1e-5f * terms;
}

}  // namespace catgs::fm
