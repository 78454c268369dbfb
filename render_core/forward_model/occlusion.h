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
// The next frame reads the map in two steps (both cores):
// - reprojection (reprojected_tile_depth), a small stage before pre-processing: for each tile of
//   the new frame, the rays through its corner pixels taken into the map's view as directions
//   (far points; a rotation maps the tile's edges to lines, so the box of the four holds the
//   tile's rays), that box widened by the parallax of its nearest occluder when the eye moved by
//   `shift` (world units): shift * focal / depth pixels, worked out twice (with the box's tiles,
//   then with the grown box's, which must need no more); the deepest map depth over the box, or
//   +inf where it leaves the last image or a corner looks behind its eye (no data: drawn);
// - per entry (entry_hidden): a small Gaussian's entry in a tile is dropped when its mean's depth
//   in the map's view, less `shift`, lies behind that tile's reprojected depth (taken 1e-3 deeper:
//   the 32-bit sort key joins depths within 3.1e-5). In the map's own frame such an entry sorted
//   behind every pixel's opaque point of the tile. A Gaussian over more than 32 tiles keeps them
//   all (the CUDA core counts and emits those from the ellipse alone);
// - nothing per whole Gaussian: a test of each Gaussian before its covariance (in the last view)
//   dropped more entries but cost more pre-processing than it saved (measured in
//   docs/history/occlusion_culling.md); a small Gaussian all of whose entries are dropped still
//   skips its SH colour.
// With the same pose (shift 0) a dropped entry would have sorted behind its tile's opaque point,
// so the picture differs from the unculled one by under 1/255 a pixel. A rotation alone changes
// no ray through the eye. A translation can open gaps between thin occluders that one depth per
// tile cannot see; that is what the parallax margin is for, and what the benchmark measures
// (catgs-bench exact-occlusion against exact on the same frames, both against the 4x supersampled
// render). A dropped entry that should have shown leaves its tile less opaque in this frame's own
// map, so the next frame draws it.
#pragma once

#include "forward_model/chunk_bounds.h"
#include "forward_model/lod.h"

namespace catgs::fm {

// The last frame's map, as the next frame's pre-processing reads it. depth null: no map (the
// first frame, a new scene or options): nothing is culled.
struct OcclusionMap {
  const float* depth = nullptr;  // [tiles_y * tiles_x], row-major, view units (+inf: not saturated)
  View view{};                   // the frame the map was drawn at
  int tiles_x = 0, tiles_y = 0;  // that frame's tile grid
  float shift = 0.0f;            // |eye of this frame - eye of view|, world units
  // Per tile of THIS frame's grid (row-major, now_tiles_x a row; null: none): the map's depth over
  // the region of the last view that the tile sees (reprojected_tile_depth), against which each of
  // a small Gaussian's entries is tested (entry_hidden).
  const float* now_depth = nullptr;
  int now_tiles_x = 0;
};

// The map drawn at view `drawn_at` as frame `now` reads it: `depth` ([tiles of drawn_at's grid], or
// null; kept as a pointer, not copied), that grid, and `shift`, the eye's move in world units
// (lod_eye of each view). now_depth is left null (the caller reprojects).
inline OcclusionMap occlusion_map(const float* depth, const View& drawn_at, const View& now) {
  OcclusionMap m;
  m.depth = depth;
  m.view = drawn_at;
  m.tiles_x = (drawn_at.width + kTileSize - 1) / kTileSize;
  m.tiles_y = (drawn_at.height + kTileSize - 1) / kTileSize;
  const glm::vec3 move = lod_eye(now) - lod_eye(drawn_at);
  m.shift = sqrtf(move.x * move.x + move.y * move.y + move.z * move.z);
  return m;
}

inline constexpr float kOcclusionDepthSlack = 1.0f + 1e-3f;      // the sort key's depth ties, with room
inline constexpr float kOcclusionTransmittance = 1.0f / 255.0f;  // a pixel is opaque below it
inline constexpr uint32_t kOcclusionRound = 256;  // entries a GPU rasterizer round stages (tune::kRasterBatch)

// The largest depth of the map over the tiles holding the pixel centres of box [u0, u1] x [w0, w1]
// of its view (pixel i's centre at i: pixels ceil(u0) .. floor(u1), at least the one at ceil(u0)),
// with the smallest in *nearest; -1 where those pixels are not all on that image or a depth is NaN.
CATGS_HD float occlusion_depth_over(const OcclusionMap& m, float u0, float u1, float w0, float w1, float* nearest) {
  if (!(u0 > -1.0f && w0 > -1.0f && u1 < static_cast<float>(m.view.width) && w1 < static_cast<float>(m.view.height)))
    return -1.0f;
  const int px0 = static_cast<int>(ceilf(u0)), py0 = static_cast<int>(ceilf(w0));
  const int px1 = static_cast<int>(floorf(u1)), py1 = static_cast<int>(floorf(w1));
  const int tx0 = px0 / kTileSize, ty0 = py0 / kTileSize;
  int tx1 = (px1 > px0 ? px1 : px0) / kTileSize, ty1 = (py1 > py0 ? py1 : py0) / kTileSize;
  tx1 = tx1 < m.tiles_x - 1 ? tx1 : m.tiles_x - 1;
  ty1 = ty1 < m.tiles_y - 1 ? ty1 : m.tiles_y - 1;
  float deepest = 0.0f, near = INFINITY;
  for (int ty = ty0; ty <= ty1; ++ty)
    for (int tx = tx0; tx <= tx1; ++tx) {
      const float d = m.depth[ty * m.tiles_x + tx];
      if (!(d >= 0.0f)) return -1.0f;
      deepest = fmaxf(deepest, d);
      near = fminf(near, d);
    }
  *nearest = near;
  return deepest;
}

// Per-entry culling (issue 72). The map's depth over what tile (tx, ty) of view `now` sees of the
// map's view: the rays through the tile's corner pixels, as directions (far points), taken into
// the map's view (a rotation maps the tile's edges to lines, so the box of its four corners holds
// its pixels' rays), that box widened by the rounding slack and by the parallax of its nearest
// occluder (shift * focal / depth pixels: worked out with the box's tiles, then again with the
// grown box's, which must need no more), and the deepest map depth over it (camera-space z of the
// map's view, world units).
// +inf where a corner looks behind the map's eye, or the box leaves its image (no data).
CATGS_HD float reprojected_tile_depth(const OcclusionMap& m, const View& now, int tx, int ty) {
  float u0 = INFINITY, u1 = -INFINITY, w0 = INFINITY, w1 = -INFINITY;
  const int last_x = (tx + 1) * kTileSize - 1 < now.width - 1 ? (tx + 1) * kTileSize - 1 : now.width - 1;
  const int last_y = (ty + 1) * kTileSize - 1 < now.height - 1 ? (ty + 1) * kTileSize - 1 : now.height - 1;
  for (int k = 0; k < 4; ++k) {  // the tile's corner pixel centres
    const float x = static_cast<float>((k & 1) ? last_x : tx * kTileSize);
    const float y = static_cast<float>((k & 2) ? last_y : ty * kTileSize);
    const glm::vec3 ray((x + 0.5f - now.cx) / now.fx, (y + 0.5f - now.cy) / now.fy, 1.0f);
    const glm::vec3 d = m.view.R * (glm::transpose(now.R) * ray);  // world direction into the map's view
    if (!(d.z > 1e-6f)) return INFINITY;
    const float u = m.view.fx * d.x / d.z + m.view.cx - 0.5f, w = m.view.fy * d.y / d.z + m.view.cy - 0.5f;
    u0 = fminf(u0, u);
    u1 = fmaxf(u1, u);
    w0 = fminf(w0, w);
    w1 = fmaxf(w1, w);
  }
  // r0: the rounding of the corners' maths (a few ulps of a pixel coordinate), so that the same
  // pose reads exactly its own tile.
  const float focal = fmaxf(m.view.fx, m.view.fy);
  const float r0 = 0.01f + 1e-6f * fmaxf(fmaxf(fabsf(u0), fabsf(u1)), fmaxf(fabsf(w0), fabsf(w1)));
  float r = r0;
  for (int pass = 0; pass < 2; ++pass) {
    float nearest = 0.0f;
    const float deepest = occlusion_depth_over(m, u0 - r, u1 + r, w0 - r, w1 + r, &nearest);
    if (!(deepest >= 0.0f)) return INFINITY;
    const float need = r0 + (m.shift > 0.0f ? m.shift * focal / nearest : 0.0f);
    if (need <= r) return deepest;
    r = need;
  }
  return INFINITY;
}

// A small Gaussian's (rect of at most kOcclusionEntryTiles tiles) entry in a tile whose
// reprojected depth is `tile_depth`: hidden when its mean's depth in the map's view, less the eye's
// move (`old_depth_less_shift`), lies behind it. In the map's own frame that entry sorted behind
// every pixel's opaque point of the tile (see above); a Gaussian over more tiles keeps them all
// (the CUDA core counts and emits those with a warp, from the ellipse alone).
inline constexpr int kOcclusionEntryTiles = 32;  // the CUDA core's tune::kBigRectTiles (static_assert there)
CATGS_HD bool entry_hidden(float tile_depth, float old_depth_less_shift) {
  return tile_depth * kOcclusionDepthSlack < old_depth_less_shift;
}

// The depth of `mean` in the map's view less the eye's move (entry_hidden's), -inf where there is
// no map of this frame's tiles.
CATGS_HD float occlusion_old_depth(glm::vec3 mean, const OcclusionMap& m) {
  if (m.depth == nullptr || m.now_depth == nullptr) return -INFINITY;
  return (m.view.R * mean + m.view.t).z - m.shift;
}

}  // namespace catgs::fm
