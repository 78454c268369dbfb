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

namespace catgs {
struct GaussianModel;
}

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

// The bounds of every chunk of `model`, in chunk order (chunk_count(model.size()) entries).
std::vector<ChunkBounds> chunk_bounds(const GaussianModel& model);

// True when no Gaussian of chunk `b` can list a tile of view `v` in the exact pipeline (see
// above). The margins (+2 px, and 1e-5 of the largest |u|, |w|) cover float rounding of the
// per-Gaussian maths and of this bound.
CATGS_HD bool chunk_finite(float x) { return x - x == 0.0f; }  // false for NaN and +-inf
CATGS_HD bool chunk_outside_view(const ChunkBounds& b, const View& v) {
  bool finite = chunk_finite(b.max_scale) && chunk_finite(b.q_max);
  float z_lo = INFINITY, z_hi = -INFINITY;
  glm::vec3 p[8];
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 corner((k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z);
    p[k] = v.R * corner + v.t;
    finite = finite && chunk_finite(p[k].x) && chunk_finite(p[k].y) && chunk_finite(p[k].z);
    z_lo = fminf(z_lo, p[k].z);
    z_hi = fmaxf(z_hi, p[k].z);
  }
  if (!finite) return false;                                    // never cull what the bound cannot hold
  if (z_hi <= v.near_plane || z_lo > v.far_plane) return true;  // all behind near, or all past far
  if (!(z_lo > v.near_plane)) return false;                     // straddles the near plane
  float u_lo = INFINITY, u_hi = -INFINITY, w_lo = INFINITY, w_hi = -INFINITY;
  for (int k = 0; k < 8; ++k) {
    const float u = v.fx * p[k].x / p[k].z + v.cx - 0.5f, w = v.fy * p[k].y / p[k].z + v.cy - 0.5f;
    u_lo = fminf(u_lo, u);
    u_hi = fmaxf(u_hi, u);
    w_lo = fminf(w_lo, w);
    w_hi = fmaxf(w_hi, w);
  }
  const float cx = kFrustumClamp * v.tan_half_fov.x, cy = kFrustumClamp * v.tan_half_fov.y;
  const float jf = sqrtf(v.fx * v.fx * (1.0f + cx * cx) + v.fy * v.fy * (1.0f + cy * cy)) / z_lo;
  const float slack = 2.0f + 1e-5f * fmaxf(fmaxf(fabsf(u_lo), fabsf(u_hi)), fmaxf(fabsf(w_lo), fabsf(w_hi)));
  const float r = sqrtf(fmaxf(b.q_max, 0.0f)) * (b.max_scale * jf + sqrtf(kLowPass)) + slack;
  return u_lo - r > static_cast<float>(v.width - 1) || u_hi + r < 0.0f || w_lo - r > static_cast<float>(v.height - 1) ||
         w_hi + r < 0.0f;
}

}  // namespace catgs::fm
