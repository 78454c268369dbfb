// Chunk-level view culling: a bound per run of kChunkSize consecutive Gaussians, tested against a
// view before any per-Gaussian work, so the Gaussians a frame cannot see cost next to nothing
// (issue 19: "cull whole chunks first"). Scenes that catgs-scene compact wrote are in Morton
// order, so a chunk's Gaussians lie close together and most chunks outside the view are
// culled whole; a scene in training order culls little (its chunks span the scene) but renders
// the same.
//
// The test is conservative with respect to the exact pipeline's per-Gaussian decision (a
// Gaussian behind the near plane, past the far plane, or whose opacity-aware ellipse's bounding
// box misses the image lists no tile): a chunk is culled only when every Gaussian it could hold
// would be culled, so culling chunks changes no render list and no pixel. It is the chunk form
// of forward_model.h edges_beyond (the cheap bound the sub-frame containment check trusts):
// - camera-space z is linear in the mean, so over the box of means its extremes lie at corners;
// - where the box lies wholly in front of the near plane, u = fx x / z + cx - 0.5 (and w) is a
//   ratio of linear functions with a positive denominator, whose extremes over the box also lie
//   at its corners;
// - the ellipse's half extent is at most sqrt(q_max) (max_scale ||J||_F + sqrt(0.3)) with J the
//   clamped Jacobian, ||J||_F <= sqrt(fx^2 (1 + cx^2) + fy^2 (1 + cy^2)) / z_min for the clamp
//   limits c = 1.3 tan_half_fov; q_max and max_scale are the chunk's largest.
// A chunk whose bound is not finite (a NaN or infinite mean, scale or opacity among its
// Gaussians, or a corner that overflows) is never culled.
#pragma once

#include <cstddef>
#include <vector>

#include "forward_model/forward_model.h"

namespace catgs::fm {

// Gaussians per chunk: Gaussians [c * kChunkSize, (c + 1) * kChunkSize) form chunk c (the last
// one may be short). The CUDA pre-processing runs a chunk per block (tunables.h).
inline constexpr int kChunkSize = 256;

// A chunk's bound, 32 bytes (two float4 loads on the GPU).
// - lo, hi: the box of the chunk's means, world units.
// - max_scale: the largest axis of any of its Gaussians, world units (exp of the largest log-scale).
// - q_max: the largest opacity-aware q_max, 2 ln(255 opacity), of any of its Gaussians.
struct alignas(16) ChunkBounds {
  glm::vec3 lo;
  float max_scale;
  glm::vec3 hi;
  float q_max;
};
static_assert(sizeof(ChunkBounds) == 32, "two float4");

// Number of chunks of n Gaussians.
CATGS_HD std::size_t chunk_count(std::size_t n) { return (n + kChunkSize - 1) / kChunkSize; }

// The CUDA core's first slot chunks for a scene of `chunks` chunks, before it has counted a view
// (cuda/records.h Projected; issue 61): a scene of up to kInitialSlotGaussians whole, a larger one
// an eighth of its chunks but at least that many Gaussians'. The server's memory estimate starts
// from it too (renderer/device_memory.h).
inline constexpr std::size_t kInitialSlotGaussians = std::size_t{4} << 20;
CATGS_HD std::size_t initial_slot_chunks(std::size_t chunks) {
  const std::size_t floor = chunk_count(kInitialSlotGaussians), eighth = chunks / 8;
  const std::size_t want = eighth > floor ? eighth : floor;
  return want < chunks ? want : chunks;
}

// The bounds of every chunk of n Gaussians held as GaussianModel holds them (means [n, 3] world
// units, log_scales [n, 3], opacity_logits [n]), in chunk order (chunk_count(n) entries).
// scene/scene_bounds.h chunk_bounds_of(model) passes a model's arrays.
std::vector<ChunkBounds> chunk_bounds(const float* means, const float* log_scales, const float* opacity_logits,
                                      std::size_t n);
// The bound of Gaussians [begin, end) of the same arrays (chunk_bounds' per chunk; an empty run
// gives the empty box: lo +inf, hi -inf).
ChunkBounds run_bound(const float* means, const float* log_scales, const float* opacity_logits, std::size_t begin,
                      std::size_t end);

// Where a chunk's means land in view `v`: `not_in_front` when every one lies behind the near
// plane or past the far plane; `unbounded` when the bound cannot say (not finite, or the box
// straddles the near plane, so a mean may project anywhere); else `box`, the pixel box of every
// mean in front of the near plane (u = fx x / z + cx - 0.5, w likewise), and z_lo > near.
struct ChunkOnScreen {
  enum Kind { not_in_front, unbounded, box } kind;
  float u_lo, u_hi, w_lo, w_hi, z_lo;
};
CATGS_HD bool chunk_finite(float x) { return x - x == 0.0f; }  // false for NaN and +-inf
CATGS_HD ChunkOnScreen chunk_on_screen(const ChunkBounds& b, const View& v) {
  ChunkOnScreen s{ChunkOnScreen::unbounded, INFINITY, -INFINITY, INFINITY, -INFINITY, INFINITY};
  bool finite = chunk_finite(b.max_scale) && chunk_finite(b.q_max);
  float z_hi = -INFINITY;
  glm::vec3 p[8];
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner((k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z);
    p[k] = v.R * corner + v.t;
    finite = finite && chunk_finite(p[k].x) && chunk_finite(p[k].y) && chunk_finite(p[k].z);
    s.z_lo = fminf(s.z_lo, p[k].z);
    z_hi = fmaxf(z_hi, p[k].z);
  }
  if (!finite) return s;  // never cull what the bound cannot hold
  if (z_hi <= v.near_plane || s.z_lo > v.far_plane) {
    s.kind = ChunkOnScreen::not_in_front;
    return s;
  }
  if (!(s.z_lo > v.near_plane)) return s;  // straddles the near plane
  for (int k = 0; k < 8; ++k) {
    const float u = v.fx * p[k].x / p[k].z + v.cx - 0.5f, w = v.fy * p[k].y / p[k].z + v.cy - 0.5f;
    s.u_lo = fminf(s.u_lo, u);
    s.u_hi = fmaxf(s.u_hi, u);
    s.w_lo = fminf(s.w_lo, w);
    s.w_hi = fmaxf(s.w_hi, w);
  }
  s.kind = ChunkOnScreen::box;
  return s;
}

// The largest ellipse half extent (pixels) of any Gaussian of chunk `b` in front of z_lo, before
// margins: sqrt(q_max) (max_scale ||J||_F + sqrt(0.3)), ||J||_F at the clamp limits (see above).
// The margin covering float rounding of the per-Gaussian maths and of this bound: 2 px and 1e-5
// of the largest |u|, |w|.
CATGS_HD float chunk_half_extent(const ChunkBounds& b, const View& v, float z_lo) {
  const float cx = kFrustumClamp * v.tan_half_fov.x, cy = kFrustumClamp * v.tan_half_fov.y;
  const float jf = sqrtf(v.fx * v.fx * (1.0f + cx * cx) + v.fy * v.fy * (1.0f + cy * cy)) / z_lo;
  return sqrtf(fmaxf(b.q_max, 0.0f)) * (b.max_scale * jf + sqrtf(kLowPass));
}
// The same bound per image axis, for a chunk whose means land in the pixel box s (kind box): the
// half extents along u and w, sqrt(q_max) (max_scale |J row| + sqrt(0.3)), each row of J at the
// box's largest |x / z| (|y / z|: the ratio's extremes over the box of means lie at its corners,
// as u's and w's do), clamped as covariance_2d clamps it, and at z_lo. Tighter than
// chunk_half_extent's norm at the clamp limits (a chunk near the image's centre: about 1.85x a
// side at 16:9); the occlusion test reads the map over this box (occlusion.h chunk_hidden).
CATGS_HD glm::vec2 chunk_half_extents(const ChunkBounds& b, const ChunkOnScreen& s, const View& v) {
  const float ax = fmaxf(fabsf(s.u_lo + 0.5f - v.cx), fabsf(s.u_hi + 0.5f - v.cx)) / v.fx;
  const float ay = fmaxf(fabsf(s.w_lo + 0.5f - v.cy), fabsf(s.w_hi + 0.5f - v.cy)) / v.fy;
  const float tx = fminf(kFrustumClamp * v.tan_half_fov.x, ax), ty = fminf(kFrustumClamp * v.tan_half_fov.y, ay);
  const float sq = sqrtf(fmaxf(b.q_max, 0.0f)), low = sqrtf(kLowPass);
  return glm::vec2(sq * (b.max_scale * v.fx * sqrtf(1.0f + tx * tx) / s.z_lo + low),
                   sq * (b.max_scale * v.fy * sqrtf(1.0f + ty * ty) / s.z_lo + low));
}
CATGS_HD float chunk_rounding_slack(const ChunkOnScreen& s) {
  return 2.0f + 1e-5f * fmaxf(fmaxf(fabsf(s.u_lo), fabsf(s.u_hi)), fmaxf(fabsf(s.w_lo), fabsf(s.w_hi)));
}
// The image edges a box widened by r lies beyond, as fm::edges_beyond's bits (1 left, 2 right,
// 4 top, 8 bottom).
CATGS_HD unsigned chunk_edges_beyond(const ChunkOnScreen& s, float r, const View& v) {
  return (s.u_hi + r < 0.0f ? 1u : 0u) | (s.u_lo - r > static_cast<float>(v.width - 1) ? 2u : 0u) |
         (s.w_hi + r < 0.0f ? 4u : 0u) | (s.w_lo - r > static_cast<float>(v.height - 1) ? 8u : 0u);
}

// True when no Gaussian of chunk `b` can list a tile of view `v` in the exact pipeline (see
// above).
CATGS_HD bool chunk_outside_view(const ChunkBounds& b, const View& v) {
  const ChunkOnScreen s = chunk_on_screen(b, v);
  if (s.kind != ChunkOnScreen::box) return s.kind == ChunkOnScreen::not_in_front;
  return chunk_edges_beyond(s, chunk_half_extent(b, v, s.z_lo) + chunk_rounding_slack(s), v) != 0u;
}

// The speculation planner's form (M, the largest screen motion of a mean on the key image:
// cpu::max_screen_motion): true when no mean of chunk `b` counts for M at view `v`, which takes
// the means in front of it deeper than `min_depth` whose centre u = fx x / z + cx, w =
// fy y / z + cy lies on the image, [0, W] x [0, H] (centres only: no radius, no half-pixel
// shift). Either every corner of the box of means lies at depth below min_depth by more than the
// rounding of a mean's depth (1e-5 of its terms), or the box lies in front of the near plane and
// its centres' pixel box lies beyond one image edge by more than chunk_rounding_slack.
CATGS_HD bool chunk_means_off_image(const ChunkBounds& b, const View& v, float min_depth) {
  float z_hi = -INFINITY, size = 0.0f;
  bool finite = true;
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner((k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z);
    const float z = (v.R * corner + v.t).z;
    finite = finite && chunk_finite(z);
    z_hi = fmaxf(z_hi, z);
    size = fmaxf(size, fabsf(corner.x) + fabsf(corner.y) + fabsf(corner.z) + fabsf(v.t.z));
  }
  if (finite && z_hi + 1e-5f * size < min_depth) return true;
  const ChunkOnScreen s = chunk_on_screen(b, v);
  if (s.kind != ChunkOnScreen::box) return false;  // not in front may still lie past the far plane
  const float r = chunk_rounding_slack(s);
  return s.u_hi + 0.5f + r < 0.0f || s.u_lo + 0.5f - r > static_cast<float>(v.width) || s.w_hi + 0.5f + r < 0.0f ||
         s.w_lo + 0.5f - r > static_cast<float>(v.height);
}

// The catgs key frame's form (the speculative pre-processing, paper sec. 3.1): true when no
// Gaussian of chunk `b` survives its per-Gaussian cull over the path of `count` views
// (view_at(k), the key view first). A Gaussian is dropped there when it is not in front of the
// key view, or (path_misses_image) when at every view where it is in front it lies beyond one
// same image edge by more than widen (r + 1) + extra, where r is its half extent and extra =
// margin_px + 1 + motion_margin |uw - u0|, the last term where it is in front of the last view
// (its centre's motion from the key view to the last). The chunk form bounds each term over the
// chunk: r by chunk_half_extent, |uw - u0| by the farthest corners of the two views' boxes; a
// view where every mean lies out of front constrains nothing, one the box straddles keeps the
// chunk.
template <typename ViewAt>
CATGS_HD bool chunk_misses_path(const ChunkBounds& b, int count, ViewAt view_at, float widen, float margin_px,
                                float motion_margin) {
  const ChunkOnScreen key = chunk_on_screen(b, view_at(0));
  if (key.kind != ChunkOnScreen::box) return key.kind == ChunkOnScreen::not_in_front;
  float extra = margin_px + 1.0f;
  const ChunkOnScreen last = chunk_on_screen(b, view_at(count - 1));
  if (last.kind == ChunkOnScreen::unbounded) return false;
  if (last.kind == ChunkOnScreen::box) {
    const float dx = fmaxf(fabsf(last.u_hi - key.u_lo), fabsf(key.u_hi - last.u_lo));
    const float dy = fmaxf(fabsf(last.w_hi - key.w_lo), fabsf(key.w_hi - last.w_lo));
    extra += motion_margin * sqrtf(dx * dx + dy * dy);
  }
  unsigned beyond = 0xfu;
  for (int k = 0; k < count && beyond != 0u; ++k) {
    const View& v = view_at(k);
    const ChunkOnScreen s = k == 0 ? key : chunk_on_screen(b, v);
    if (s.kind == ChunkOnScreen::not_in_front) continue;
    if (s.kind == ChunkOnScreen::unbounded) return false;
    const float r = widen * (chunk_half_extent(b, v, s.z_lo) + 1.0f) + extra + chunk_rounding_slack(s);
    beyond &= chunk_edges_beyond(s, r, v);
  }
  return beyond != 0u;
}

}  // namespace catgs::fm
