// Occlusion culling from the session's last frame (issue 72): a chunk that lay wholly behind
// where the last frame's tiles became opaque is not pre-processed, listed or sorted this frame.
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
// - a split tile (task splitting): the end of the slice after which its last pixel's composed
//   transmittance got there (the merge's product), so slice-granular.
// Both cores compute P the same way from the same list; alpha's few-ulp rounding can move a
// pixel's crossing by an entry, and so P by a round, where it falls on a round's edge.
//
// The test (chunk_occluded), per chunk of the new frame, in the map's own view: the chunk's box
// of means projected there (chunk_on_screen), widened by its Gaussians' largest half extent
// (chunk_half_extent) and the rounding slack, must lie wholly on that frame's image, and every
// tile it covers must have become opaque in front of the chunk's nearest mean, with margins:
// - depth ties of the 32-bit sort key (fm::single_sort_packing joins depths within 3.1e-5 of
//   each other): the map's depth is taken 1e-3 deeper;
// - the eye's move between the two frames, `shift` (world units): the chunk is taken `shift`
//   nearer, and the widened box grows by the parallax of the nearest occluder it covers,
//   shift * focal / depth pixels (a point at depth d moves on the image by at most that much
//   against any point behind it when the eye moves by `shift`), worked out twice: with the box's
//   own tiles, then with the tiles of the grown box, which must need no more.
// A rotation alone changes no ray through the eye, so with shift = 0 the test holds up to the
// margins: a culled chunk would have been sorted behind every pixel's opaque point, and the
// picture differs from the unculled one by under 1/255 a pixel. A translation can open gaps
// between thin occluders that one depth per tile cannot see; that is what the margins grow with
// the move for, and what the benchmark measures (catgs-bench --occlusion-cull: every frame
// against the unculled render). Where the map has no data (the chunk reaches past the last
// image's edges, straddles its near plane or is not finite) the chunk is drawn. A culled chunk
// that should have shown leaves its tiles less opaque this frame, so the next frame draws it.
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
};

// The map drawn at view `drawn_at` (`depth`: its tiles' depths) as frame `now` reads it.
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

inline constexpr float kOcclusionDepthSlack = 1.0f + 1e-3f;  // the sort key's depth ties, with room
inline constexpr float kOcclusionTransmittance = 1.0f / 255.0f;  // a pixel is opaque below it
inline constexpr uint32_t kOcclusionRound = 256;  // entries a GPU rasterizer round stages (tune::kRasterBatch)

// The largest depth of the map over the tiles covering pixel box [u0, u1] x [w0, w1] of its view,
// with the smallest in *nearest; -1 where the box is not wholly on that image or a depth is NaN.
CATGS_HD float occlusion_depth_over(const OcclusionMap& m, float u0, float u1, float w0, float w1, float* nearest) {
  if (!(u0 >= 0.0f && w0 >= 0.0f && u1 <= static_cast<float>(m.view.width - 1) &&
        w1 <= static_cast<float>(m.view.height - 1)))
    return -1.0f;
  const int tx0 = static_cast<int>(u0) / kTileSize, ty0 = static_cast<int>(w0) / kTileSize;
  int tx1 = static_cast<int>(u1) / kTileSize, ty1 = static_cast<int>(w1) / kTileSize;
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

// True when pixel box s of the map's view (the means' box, z_lo their nearest depth), widened by
// r0, lies wholly behind the map's opaque tiles with the margins above; false whenever the map
// cannot say.
CATGS_HD bool box_occluded(const ChunkOnScreen& s, float r0, const OcclusionMap& m) {
  if (s.kind != ChunkOnScreen::box) return false;
  const float z = s.z_lo - m.shift;  // the nearest mean, as near as the move can bring it
  const float focal = fmaxf(m.view.fx, m.view.fy);
  float r = r0;
  for (int pass = 0; pass < 2; ++pass) {
    float nearest = 0.0f;
    const float deepest = occlusion_depth_over(m, s.u_lo - r, s.u_hi + r, s.w_lo - r, s.w_hi + r, &nearest);
    // Not on the last image, or some covered tile became opaque no nearer than the box.
    if (!(deepest >= 0.0f && deepest * kOcclusionDepthSlack < z)) return false;
    const float need = r0 + (m.shift > 0.0f ? m.shift * focal / nearest : 0.0f);
    if (need <= r) return true;
    r = need;
  }
  return false;
}

// Chunk `b` wholly behind the map's opaque tiles (see above).
CATGS_HD bool chunk_occluded(const ChunkBounds& b, const OcclusionMap& m) {
  if (m.depth == nullptr) return false;
  const ChunkOnScreen s = chunk_on_screen(b, m.view);
  return box_occluded(s, chunk_half_extent(b, m.view, s.z_lo) + chunk_rounding_slack(s), m);
}

// One Gaussian (mean in world units, its largest axis `max_scale` in world units, its q_max) wholly
// behind the map's opaque tiles: chunk_occluded of the box of its one mean, worked out from one
// projection instead of eight corners. Pre-processing asks it before the Gaussian's covariance.
CATGS_HD bool gaussian_occluded(glm::vec3 mean, float max_scale, float q_max, const OcclusionMap& m) {
  if (m.depth == nullptr) return false;
  const glm::vec3 p = m.view.R * mean + m.view.t;
  if (!(p.z > m.view.near_plane) || !chunk_finite(p.x) || !chunk_finite(p.y) || !chunk_finite(max_scale) ||
      !chunk_finite(q_max))
    return false;
  ChunkOnScreen s;
  s.kind = ChunkOnScreen::box;
  s.u_lo = s.u_hi = m.view.fx * p.x / p.z + m.view.cx - 0.5f;
  s.w_lo = s.w_hi = m.view.fy * p.y / p.z + m.view.cy - 0.5f;
  s.z_lo = p.z;
  const ChunkBounds b{mean, max_scale, mean, q_max};
  return box_occluded(s, chunk_half_extent(b, m.view, p.z) + chunk_rounding_slack(s), m);
}

}  // namespace catgs::fm
