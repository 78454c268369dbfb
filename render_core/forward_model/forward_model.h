// The forward model of 3DGS, shared by the CPU reference and the CUDA core so both compute the
// same numbers (DESIGN.md "Forward model"; Kerbl et al. 2023, EWA splatting, Zwicker et al. 2001).
// Every function is plain float maths, callable from host and device.
//
// Screen coordinates ("pixel units"): pixel (i, j) has its centre at (i, j); the projected mean
// of a camera-space point is (fx * x / z + cx - 0.5, fy * y / z + cy - 0.5), the reference 3DGS
// convention for a principal point (cx, cy) given in continuous image coordinates.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include <glm/glm.hpp>

#if defined(__CUDACC__)
#define CATGS_HD __host__ __device__ __forceinline__
#else
#define CATGS_HD inline
#endif

namespace catgs::fm {

inline constexpr int kTileSize = 16;                  // tiles of 16 x 16 pixels
inline constexpr float kMinAlpha = 1.0f / 255.0f;     // alpha below this is skipped
inline constexpr float kMaxAlpha = 0.99f;             // alpha is clamped to this
inline constexpr float kMinTransmittance = 1e-4f;     // a pixel stops before T would drop below
inline constexpr float kLowPass = 0.3f;               // px^2 added to the 2D covariance diagonal
inline constexpr float kFrustumClamp = 1.3f;          // Jacobian clamped to 1.3x the fov
// The exact tile test includes tiles whose best pixel has q slightly above the alpha threshold, so
// float rounding in exp() can never drop a pixel the rasterizer would blend.
inline constexpr float kExactQMargin = 1e-3f;

// Rotation matrix (row-major maths, returned as glm column-major) of quaternion (w, x, y, z).
CATGS_HD glm::mat3 quat_to_mat(glm::vec4 q) {
  const float n = sqrtf(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  q = n > 0.0f ? q / n : glm::vec4(1.0f, 0.0f, 0.0f, 0.0f);
  const float w = q.x, x = q.y, y = q.z, z = q.w;
  // glm::mat3(c0, c1, c2) takes columns.
  return glm::mat3(1.f - 2.f * (y * y + z * z), 2.f * (x * y + w * z), 2.f * (x * z - w * y),
                   2.f * (x * y - w * z), 1.f - 2.f * (x * x + z * z), 2.f * (y * z + w * x),
                   2.f * (x * z + w * y), 2.f * (y * z - w * x), 1.f - 2.f * (x * x + y * y));
}

// World 3D covariance Sigma = R S S^T R^T from log-scales and a (w, x, y, z) quaternion;
// returned as its 6 unique entries (xx, xy, xz, yy, yz, zz).
struct Cov3 { float xx, xy, xz, yy, yz, zz; };
CATGS_HD Cov3 covariance_3d(glm::vec3 log_scale, glm::vec4 rotation_wxyz) {
  const glm::mat3 R = quat_to_mat(rotation_wxyz);
  const glm::vec3 s(expf(log_scale.x), expf(log_scale.y), expf(log_scale.z));
  glm::mat3 M;  // M = R * S (scale each column)
  M[0] = R[0] * s.x;
  M[1] = R[1] * s.y;
  M[2] = R[2] * s.z;
  const glm::mat3 S = M * glm::transpose(M);
  return {S[0][0], S[1][0], S[2][0], S[1][1], S[2][1], S[2][2]};
}

// 2D screen covariance (a, b, c) = [[a, b], [b, c]], pixels^2, of a Gaussian whose mean is at
// camera-space `p_cam`, by EWA: J W Sigma W^T J^T with W the world-to-camera rotation and the
// perspective Jacobian J evaluated at the mean clamped to 1.3x the field of view; +0.3 px^2 on the
// diagonal (low-pass filter). tan_half_fov = (W / (2 fx), H / (2 fy)).
CATGS_HD glm::vec3 covariance_2d(const Cov3& S, const glm::mat3& W, glm::vec3 p_cam, float fx,
                                 float fy, glm::vec2 tan_half_fov) {
  const float lim_x = kFrustumClamp * tan_half_fov.x;
  const float lim_y = kFrustumClamp * tan_half_fov.y;
  const float z = p_cam.z;
  const float x = fminf(lim_x, fmaxf(-lim_x, p_cam.x / z)) * z;
  const float y = fminf(lim_y, fmaxf(-lim_y, p_cam.y / z)) * z;
  // Rows of J (2 x 3).
  const glm::vec3 j0(fx / z, 0.0f, -fx * x / (z * z));
  const glm::vec3 j1(0.0f, fy / z, -fy * y / (z * z));
  // T = J W: rows t_r = j_r^T W, i.e. t_r[k] = sum_m j_r[m] W[m][k] (W[m][k]: row m, col k).
  const glm::mat3 Wt = glm::transpose(W);  // columns of Wt are the rows of W
  const glm::vec3 t0 = j0.x * Wt[0] + j0.y * Wt[1] + j0.z * Wt[2];
  const glm::vec3 t1 = j1.x * Wt[0] + j1.y * Wt[1] + j1.z * Wt[2];
  const glm::mat3 Sig(S.xx, S.xy, S.xz, S.xy, S.yy, S.yz, S.xz, S.yz, S.zz);
  const glm::vec3 St0 = Sig * t0, St1 = Sig * t1;
  return glm::vec3(glm::dot(t0, St0) + kLowPass, glm::dot(t0, St1), glm::dot(t1, St1) + kLowPass);
}

// Conic = inverse of the 2D covariance, (A, B, C) with q(d) = A dx^2 + 2 B dx dy + C dy^2.
// Returns false when the covariance is singular.
CATGS_HD bool conic_from_cov2d(glm::vec3 cov, glm::vec3* conic) {
  const float det = cov.x * cov.z - cov.y * cov.y;
  if (det == 0.0f) return false;
  const float inv = 1.0f / det;
  *conic = glm::vec3(cov.z * inv, -cov.y * inv, cov.x * inv);
  return true;
}

// Quadratic form q(d) = d^T conic d; alpha(d) = min(0.99, opacity * exp(-q / 2)).
CATGS_HD float conic_quadratic(glm::vec3 conic, float dx, float dy) {
  return conic.x * dx * dx + 2.0f * conic.y * dx * dy + conic.z * dy * dy;
}

// The reference 3DGS's "power" (-q/2), written as it does so float rounding matches.
CATGS_HD float gaussian_power(glm::vec3 conic, float dx, float dy) {
  return -0.5f * (conic.x * dx * dx + conic.z * dy * dy) - conic.y * dx * dy;
}

// vanilla: 3-sigma radius in pixels from the larger eigenvalue of the 2D covariance (reference 3DGS).
CATGS_HD float three_sigma_radius(glm::vec3 cov) {
  const float det = cov.x * cov.z - cov.y * cov.y;
  const float mid = 0.5f * (cov.x + cov.z);
  const float root = sqrtf(fmaxf(0.1f, mid * mid - det));
  const float lambda = fmaxf(mid + root, mid - root);
  return ceilf(3.0f * sqrtf(lambda));
}

// Tile rectangle [min, max) in tile units (x0, y0, x1, y1), clamped to the grid.
struct TileRect { int x0, y0, x1, y1; };
CATGS_HD int tile_count(const TileRect& r) {
  return (r.x1 > r.x0 && r.y1 > r.y0) ? (r.x1 - r.x0) * (r.y1 - r.y0) : 0;
}

// vanilla: the reference 3DGS getRect over a square of half-size `radius` around `mean`.
CATGS_HD TileRect square_tile_rect(glm::vec2 mean, float radius, int grid_w, int grid_h) {
  auto clampi = [](int v, int hi) { return v < 0 ? 0 : (v > hi ? hi : v); };
  return {clampi(static_cast<int>((mean.x - radius) / kTileSize), grid_w),
          clampi(static_cast<int>((mean.y - radius) / kTileSize), grid_h),
          clampi(static_cast<int>((mean.x + radius + kTileSize - 1) / kTileSize), grid_w),
          clampi(static_cast<int>((mean.y + radius + kTileSize - 1) / kTileSize), grid_h)};
}

// exact: q_max such that opacity * exp(-q / 2) >= 1/255 <=> q <= q_max = 2 ln(255 opacity).
// Negative when the Gaussian can never reach alpha 1/255 (cull it).
CATGS_HD float opacity_aware_qmax(float opacity) { return 2.0f * logf(255.0f * opacity); }

// exact: tiles holding pixel centres inside the ellipse q <= q_max (bounding box half-widths
// sqrt(q_max * cov_xx), sqrt(q_max * cov_yy)), clamped to the grid.
CATGS_HD TileRect ellipse_tile_rect(glm::vec2 mean, glm::vec3 cov, float q_max, int width,
                                    int height) {
  const float hx = sqrtf(q_max * cov.x), hy = sqrtf(q_max * cov.z);
  const float px0 = fmaxf(0.0f, ceilf(mean.x - hx)), py0 = fmaxf(0.0f, ceilf(mean.y - hy));
  const float px1 = fminf(static_cast<float>(width - 1), floorf(mean.x + hx));
  const float py1 = fminf(static_cast<float>(height - 1), floorf(mean.y + hy));
  if (px1 < px0 || py1 < py0) return {0, 0, 0, 0};
  return {static_cast<int>(px0) / kTileSize, static_cast<int>(py0) / kTileSize,
          static_cast<int>(px1) / kTileSize + 1, static_cast<int>(py1) / kTileSize + 1};
}

// Minimum of the positive definite q(d) over the rectangle dx in [x0, x1], dy in [y0, y1]
// (d = pixel - mean): zero inside, else the least of the four edges' 1D minima.
CATGS_HD float min_quadratic_over_rect(glm::vec3 conic, float x0, float x1, float y0, float y1) {
  if (x0 <= 0.0f && 0.0f <= x1 && y0 <= 0.0f && 0.0f <= y1) return 0.0f;
  auto clampf = [](float v, float lo, float hi) { return fminf(hi, fmaxf(lo, v)); };
  float best = INFINITY;
  const float xs[2] = {x0, x1}, ys[2] = {y0, y1};
  for (int e = 0; e < 2; ++e) {
    const float dy = clampf(-conic.y * xs[e] / conic.z, y0, y1);  // edge dx = xs[e]
    best = fminf(best, conic_quadratic(conic, xs[e], dy));
    const float dx = clampf(-conic.y * ys[e] / conic.x, x0, x1);  // edge dy = ys[e]
    best = fminf(best, conic_quadratic(conic, dx, ys[e]));
  }
  return best;
}

// exact: does tile (tx, ty) hold a pixel centre with q <= q_max? Pixel centres of the tile that lie
// inside the image span [tx*16, min(tx*16+15, W-1)] x [ty*16, min(ty*16+15, H-1)].
CATGS_HD bool ellipse_touches_tile(glm::vec2 mean, glm::vec3 conic, float q_max, int tx, int ty,
                                   int width, int height) {
  const float x0 = static_cast<float>(tx * kTileSize);
  const float y0 = static_cast<float>(ty * kTileSize);
  const float x1 = fminf(x0 + (kTileSize - 1), static_cast<float>(width - 1));
  const float y1 = fminf(y0 + (kTileSize - 1), static_cast<float>(height - 1));
  return min_quadratic_over_rect(conic, x0 - mean.x, x1 - mean.x, y0 - mean.y, y1 - mean.y) <=
         q_max + kExactQMargin;
}

// View-dependent colour from SH of degree <= 3 at unit direction `dir` (camera centre -> mean),
// + 0.5, clamped at 0 (reference 3DGS computeColorFromSH). `sh` points to K * 3 floats
// (coefficient-major) of one Gaussian.
CATGS_HD glm::vec3 sh_to_color(int degree, const float* sh, glm::vec3 dir) {
  constexpr float C0 = 0.28209479177387814f;
  constexpr float C1 = 0.4886025119029199f;
  auto c = [sh](int k) { return glm::vec3(sh[3 * k], sh[3 * k + 1], sh[3 * k + 2]); };
  glm::vec3 result = C0 * c(0);
  if (degree > 0) {
    const float x = dir.x, y = dir.y, z = dir.z;
    result = result - C1 * y * c(1) + C1 * z * c(2) - C1 * x * c(3);
    if (degree > 1) {
      const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
      result = result + 1.0925484305920792f * xy * c(4) + -1.0925484305920792f * yz * c(5) +
               0.31539156525252005f * (2.0f * zz - xx - yy) * c(6) +
               -1.0925484305920792f * xz * c(7) + 0.5462742152960396f * (xx - yy) * c(8);
      if (degree > 2) {
        result = result + -0.5900435899266435f * y * (3.0f * xx - yy) * c(9) +
                 2.890611442640554f * xy * z * c(10) +
                 -0.4570457994644658f * y * (4.0f * zz - xx - yy) * c(11) +
                 0.3731763325901154f * z * (2.0f * zz - 3.0f * xx - 3.0f * yy) * c(12) +
                 -0.4570457994644658f * x * (4.0f * zz - xx - yy) * c(13) +
                 1.445305721320277f * z * (xx - yy) * c(14) +
                 -0.5900435899266435f * x * (xx - 3.0f * yy) * c(15);
      }
    }
  }
  result += 0.5f;
  return glm::max(result, glm::vec3(0.0f));
}

CATGS_HD float sigmoid(float x) { return 1.0f / (1.0f + expf(-x)); }

// IEEE-754 bits of a float.
CATGS_HD uint32_t float_bits(float f) {
#if defined(__CUDA_ARCH__)
  return __float_as_uint(f);
#else
  uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return u;
#endif
}

// Sort key of one render-list entry: [tile id | view depth bits]; depth > 0 so its IEEE bits
// order like the float.
CATGS_HD uint64_t render_key(uint32_t tile, float depth) {
  return (static_cast<uint64_t>(tile) << 32) | static_cast<uint64_t>(float_bits(depth));
}

}  // namespace catgs::fm

// ---- Speculative pre-processing: Gaussian trails (paper sec. 3.1 "Fine-grained Intersection
// Detection"; DESIGN.md 1). A Gaussian's trail is the region its ellipse q <= q_trail sweeps when
// its centre moves along the segment mean0 -> mean0 + motion. ----
namespace catgs::fm {

// Minimum of q(d) over the segment d = a + s (b - a), s in [0, 1].
CATGS_HD float min_quadratic_on_segment(glm::vec3 conic, glm::vec2 a, glm::vec2 b) {
  const glm::vec2 e = b - a;
  const float qe = conic_quadratic(conic, e.x, e.y);
  const float be = conic.x * a.x * e.x + conic.y * (a.x * e.y + a.y * e.x) + conic.z * a.y * e.y;
  const float s = qe > 0.0f ? fminf(1.0f, fmaxf(0.0f, -be / qe)) : 0.0f;
  const glm::vec2 d = a + s * e;
  return conic_quadratic(conic, d.x, d.y);
}

// A trail's tile test (DESIGN.md 1) with its per-Gaussian constants worked out once: the key
// frame asks it for every tile of the trail's rectangle, so the divisions the minimisation needs
// are done here, not per tile. conic: the trail's inverse 2D covariance (positive definite);
// motion: mean0 -> end of the window, pixels; q_limit = q_trail + kExactQMargin.
struct TrailTileTest {
  glm::vec2 mean0, motion;
  glm::vec3 conic;
  float q_limit;
  float inv_a, inv_c;  // 1 / conic.x, 1 / conic.z
  glm::vec2 cm;        // conic * motion
  float inv_mcm;       // 1 / (motion^T conic motion); 0 for a still trail
  glm::vec2 inv_m;     // 1 / motion per axis; 0 where the motion is 0
};

CATGS_HD TrailTileTest make_trail_tile_test(glm::vec2 mean0, glm::vec2 motion, glm::vec3 conic, float q_trail) {
  TrailTileTest t;
  t.mean0 = mean0;
  t.motion = motion;
  t.conic = conic;
  t.q_limit = q_trail + kExactQMargin;
  t.inv_a = 1.0f / conic.x;
  t.inv_c = 1.0f / conic.z;
  t.cm = glm::vec2(conic.x * motion.x + conic.y * motion.y, conic.y * motion.x + conic.z * motion.y);
  const float mcm = motion.x * t.cm.x + motion.y * t.cm.y;
  t.inv_mcm = mcm > 0.0f ? 1.0f / mcm : 0.0f;
  t.inv_m = glm::vec2(motion.x != 0.0f ? 1.0f / motion.x : 0.0f, motion.y != 0.0f ? 1.0f / motion.y : 0.0f);
  return t;
}

// Minimum of the positive definite q(d) = d^T conic d over the swept rectangle {r - s m : r in
// [x0,x1]x[y0,y1], s in [0, 1]} (the Minkowski sum of the rectangle and the segment 0 -> -m,
// coordinates relative to the trail's mean0): zero if it holds the origin, else the least over
// its boundary. That boundary is each rectangle edge at s = 0 if its outward normal n has
// n . m >= 0 (it faces away from the sweep direction -m), at s = 1 if n . m <= 0, and the sweeps
// of the silhouette corners, whose two edges disagree in sign: a hexagon, 6 segments (both
// versions of an edge parallel to m, with every corner between them). Segments inside the
// polygon cannot lower the minimum of a convex q whose minimum point lies outside, so they are
// skipped. On an axis-parallel edge the minimiser is closed-form (x = -B y / A on a horizontal
// one, y = -B x / C on a vertical one), clamped to the edge; on a corner's sweep a - s m it is
// s = (a^T conic m) / (m^T conic m), clamped to [0, 1].
CATGS_HD float min_quadratic_over_swept_rect(const TrailTileTest& t, float x0, float x1, float y0, float y1) {
  const glm::vec2 m = t.motion;
  // Origin inside: some s in [0, 1] has x0 <= s mx <= x1 and y0 <= s my <= y1.
  float lo = 0.0f, hi = 1.0f;
  const float r0[2] = {x0, y0}, r1[2] = {x1, y1}, mv[2] = {m.x, m.y}, inv[2] = {t.inv_m.x, t.inv_m.y};
  for (int a = 0; a < 2 && lo <= hi; ++a) {
    if (mv[a] == 0.0f) {
      if (r0[a] > 0.0f || r1[a] < 0.0f) hi = -1.0f;
    } else {
      const float ta = r0[a] * inv[a], tb = r1[a] * inv[a];
      lo = fmaxf(lo, fminf(ta, tb));
      hi = fminf(hi, fmaxf(ta, tb));
    }
  }
  if (lo <= hi) return 0.0f;
  const glm::vec3 c = t.conic;
  auto clampf = [](float v, float a, float b) { return fminf(b, fmaxf(a, v)); };
  auto horizontal = [&](float y, float xa, float xb) {  // the edge {(x, y): xa <= x <= xb}
    return conic_quadratic(c, clampf(-c.y * y * t.inv_a, xa, xb), y);
  };
  auto vertical = [&](float x, float ya, float yb) {
    return conic_quadratic(c, x, clampf(-c.y * x * t.inv_c, ya, yb));
  };
  auto sweep = [&](float ax, float ay) {  // the corner (ax, ay) swept to (ax, ay) - m
    const float s = clampf((ax * t.cm.x + ay * t.cm.y) * t.inv_mcm, 0.0f, 1.0f);
    return conic_quadratic(c, ax - s * m.x, ay - s * m.y);
  };
  // n . m of the outward normals of the edges y = y0, x = x1, y = y1, x = x0.
  const float bottom = -m.y, right = m.x, top = m.y, left = -m.x;
  float best = INFINITY;
  if (bottom >= 0.0f) best = fminf(best, horizontal(y0, x0, x1));
  if (bottom <= 0.0f) best = fminf(best, horizontal(y0 - m.y, x0 - m.x, x1 - m.x));
  if (top >= 0.0f) best = fminf(best, horizontal(y1, x0, x1));
  if (top <= 0.0f) best = fminf(best, horizontal(y1 - m.y, x0 - m.x, x1 - m.x));
  if (right >= 0.0f) best = fminf(best, vertical(x1, y0, y1));
  if (right <= 0.0f) best = fminf(best, vertical(x1 - m.x, y0 - m.y, y1 - m.y));
  if (left >= 0.0f) best = fminf(best, vertical(x0, y0, y1));
  if (left <= 0.0f) best = fminf(best, vertical(x0 - m.x, y0 - m.y, y1 - m.y));
  // A corner is on the silhouette when its two edges face opposite ways.
  if (left * bottom <= 0.0f) best = fminf(best, sweep(x0, y0));
  if (bottom * right <= 0.0f) best = fminf(best, sweep(x1, y0));
  if (right * top <= 0.0f) best = fminf(best, sweep(x1, y1));
  if (top * left <= 0.0f) best = fminf(best, sweep(x0, y1));
  return best;
}

// Does tile (tx, ty) hold a pixel centre inside the trail: the ellipse (conic, q_trail) whose
// centre moves from mean0 by `motion` (pixels)? Exact for that swept shape (up to
// kExactQMargin); conservative for a Gaussian whose own ellipse along the path stays inside it
// (see trail_contains).
CATGS_HD bool trail_touches_tile(const TrailTileTest& t, int tx, int ty, int width, int height) {
  const float x0 = static_cast<float>(tx * kTileSize), y0 = static_cast<float>(ty * kTileSize);
  const float x1 = fminf(x0 + (kTileSize - 1), static_cast<float>(width - 1));
  const float y1 = fminf(y0 + (kTileSize - 1), static_cast<float>(height - 1));
  return min_quadratic_over_swept_rect(t, x0 - t.mean0.x, x1 - t.mean0.x, y0 - t.mean0.y, y1 - t.mean0.y) <=
         t.q_limit;
}

// The same, for a caller that asks about one tile (it pays the per-Gaussian divisions each time).
CATGS_HD bool trail_touches_tile(glm::vec2 mean0, glm::vec2 motion, glm::vec3 conic, float q_trail, int tx,
                                 int ty, int width, int height) {
  return trail_touches_tile(make_trail_tile_test(mean0, motion, conic, q_trail), tx, ty, width, height);
}

// Tiles of the bounding box of a trail: both end ellipses (cov = the trail's 2D covariance).
CATGS_HD TileRect trail_tile_rect(glm::vec2 mean0, glm::vec2 motion, glm::vec3 cov, float q_trail,
                                  int width, int height) {
  // The box of the swept shape: both end ellipses' boxes and all between (either end may lie
  // off screen while the path crosses it).
  const float hx = sqrtf(q_trail * cov.x), hy = sqrtf(q_trail * cov.z);
  const glm::vec2 lo = glm::min(mean0, mean0 + motion) - glm::vec2(hx, hy);
  const glm::vec2 hi = glm::max(mean0, mean0 + motion) + glm::vec2(hx, hy);
  const float px0 = fmaxf(0.0f, ceilf(lo.x)), py0 = fmaxf(0.0f, ceilf(lo.y));
  const float px1 = fminf(static_cast<float>(width - 1), floorf(hi.x));
  const float py1 = fminf(static_cast<float>(height - 1), floorf(hi.y));
  if (px1 < px0 || py1 < py0) return {0, 0, 0, 0};
  return {static_cast<int>(px0) / kTileSize, static_cast<int>(py0) / kTileSize,
          static_cast<int>(px1) / kTileSize + 1, static_cast<int>(py1) / kTileSize + 1};
}

// A 2D covariance that dominates both a and b (U - a and U - b positive semidefinite): a plus the
// positive part of b - a. Equals a when b == a, so a still camera keeps the exact ellipse.
CATGS_HD glm::vec3 dominating_cov2d(glm::vec3 a, glm::vec3 b) {
  const float dx = b.x - a.x, dy = b.y - a.y, dz = b.z - a.z;  // D = [[dx, dy], [dy, dz]]
  const float mid = 0.5f * (dx + dz);
  const float rad = sqrtf(fmaxf(0.0f, 0.25f * (dx - dz) * (dx - dz) + dy * dy));
  const float l1 = mid + rad, l2 = mid - rad;  // eigenvalues, l1 >= l2
  if (l2 >= 0.0f) return b;                    // b >= a: b dominates
  if (l1 <= 0.0f) return a;                    // a >= b
  // Positive part l1 * v v^T with v the eigenvector of l1.
  glm::vec2 v = fabsf(dy) > 1e-12f ? glm::vec2(dy, l1 - dx) : (dx >= dz ? glm::vec2(1, 0) : glm::vec2(0, 1));
  v /= sqrtf(v.x * v.x + v.y * v.y);
  return a + l1 * glm::vec3(v.x * v.x, v.x * v.y, v.y * v.y);
}

// Sub-frame check that a Gaussian's actual ellipse (centre `mean`, covariance `cov`, level q_max)
// lies inside its key frame's trail (centre mean0 -> mean0 + motion, covariance `trail_cov`, level
// q_trail): with lambda the largest generalised eigenvalue of (cov, trail_cov) and delta the
// offset of `mean` from the nearest point of the path in the trail_cov metric,
//   sqrt(lambda * q_max) + sqrt(delta^T trail_cov^-1 delta) <= sqrt(q_trail)
// is sufficient (support functions, Cauchy-Schwarz). False: render this frame as a key frame.
CATGS_HD bool trail_contains(glm::vec2 mean0, glm::vec2 motion, glm::vec3 trail_cov, float q_trail,
                             glm::vec2 mean, glm::vec3 cov, float q_max) {
  glm::vec3 trail_conic;
  if (!conic_from_cov2d(trail_cov, &trail_conic)) return false;
  const float det_u = trail_cov.x * trail_cov.z - trail_cov.y * trail_cov.y;
  const float det_a = cov.x * cov.z - cov.y * cov.y;
  const float bq = cov.x * trail_cov.z + cov.z * trail_cov.x - 2.0f * cov.y * trail_cov.y;
  const float lambda = (bq + sqrtf(fmaxf(0.0f, bq * bq - 4.0f * det_u * det_a))) / (2.0f * det_u);
  const float off = min_quadratic_on_segment(trail_conic, mean - mean0, mean - mean0 - motion);
  return sqrtf(fmaxf(0.0f, lambda) * q_max) + sqrtf(off) <= sqrtf(q_trail);
}

// The exact sub-frame check behind trail_contains(), which is only sufficient: every tile the
// actual ellipse reaches at this pose (ellipse_touches_tile, as the exact pipeline lists it) is a
// tile the key frame listed the Gaussian in (trail_touches_tile). A small Gaussian that strays a
// fraction of a pixel off its predicted trail but stays within its listed tiles renders exactly
// as a full key frame would, so it need not force one. Cost: two tile tests per reached tile;
// callers try trail_contains() first.
CATGS_HD bool listed_tiles_cover(glm::vec2 mean0, glm::vec2 motion, glm::vec3 trail_conic, float q_trail,
                                 glm::vec2 mean, glm::vec3 cov, glm::vec3 conic, float q_max, int width,
                                 int height) {
  const TileRect r = ellipse_tile_rect(mean, cov, q_max, width, height);
  for (int ty = r.y0; ty < r.y1; ++ty)
    for (int tx = r.x0; tx < r.x1; ++tx)
      if (ellipse_touches_tile(mean, conic, q_max, tx, ty, width, height) &&
          !trail_touches_tile(mean0, motion, trail_conic, q_trail, tx, ty, width, height))
        return false;
  return true;
}

// Does the ellipse (2D covariance `cov`, conic, level q_max) reach a pixel centre of a width x
// height image? Exactly when the exact pipeline would list it in some tile.
CATGS_HD bool ellipse_reaches_image(glm::vec2 mean, glm::vec3 cov, glm::vec3 conic, float q_max, int width,
                                    int height) {
  const TileRect r = ellipse_tile_rect(mean, cov, q_max, width, height);
  for (int ty = r.y0; ty < r.y1; ++ty)
    for (int tx = r.x0; tx < r.x1; ++tx)
      if (ellipse_touches_tile(mean, conic, q_max, tx, ty, width, height)) return true;
  return false;
}

// A cheap, conservative filter before the exact test above for a Gaussian at camera-space p_cam
// whose largest axis is max_scale (world units): false only when its EWA ellipse at level q_max
// cannot reach the image. The EWA extent along any axis is at most sqrt(q_max) * max_scale *
// ||J||_F with J the clamped Jacobian (||J||_F^2 = (fx^2 (1 + tx^2) + fy^2 (1 + ty^2)) / z^2),
// plus sqrt(q_max * 0.3) for the low-pass filter; +1 px for rounding.
//
// edges_beyond() gives the image edges the bound lies beyond, with the radius r widened to
// widen * r + extra_px: bit 0 left (u + r < 0), 1 right (u - r > W - 1), 2 top, 3 bottom. The
// speculative pre-processing culls a Gaussian that lies beyond one same edge at every sample of
// its path (path_edges_beyond below).
CATGS_HD unsigned edges_beyond(glm::vec3 p_cam, float max_scale, float q_max, float fx, float fy, float cx, float cy,
                               glm::vec2 tan_half_fov, int width, int height, float widen = 1.0f,
                               float extra_px = 0.0f) {
  const float z = p_cam.z;
  const float tx = fminf(kFrustumClamp * tan_half_fov.x, fabsf(p_cam.x / z));
  const float ty = fminf(kFrustumClamp * tan_half_fov.y, fabsf(p_cam.y / z));
  const float jf = sqrtf(fx * fx * (1.0f + tx * tx) + fy * fy * (1.0f + ty * ty)) / z;
  const float r = widen * (sqrtf(q_max) * (max_scale * jf + sqrtf(kLowPass)) + 1.0f) + extra_px;
  const float u = fx * p_cam.x / z + cx - 0.5f, v = fy * p_cam.y / z + cy - 0.5f;
  return (u + r < 0.0f ? 1u : 0u) | (u - r > static_cast<float>(width - 1) ? 2u : 0u) |
         (v + r < 0.0f ? 4u : 0u) | (v - r > static_cast<float>(height - 1) ? 8u : 0u);
}
CATGS_HD bool may_reach_image(glm::vec3 p_cam, float max_scale, float q_max, float fx, float fy, float cx, float cy,
                              glm::vec2 tan_half_fov, int width, int height) {
  return edges_beyond(p_cam, max_scale, q_max, fx, fy, cx, cy, tan_half_fov, width, height) == 0u;
}

// Largest axis of a Gaussian, world units: exp of its largest log-scale.
CATGS_HD float max_scale_of(const float* log_scale) {
  return expf(fmaxf(log_scale[0], fmaxf(log_scale[1], log_scale[2])));
}

// A Gaussian (mean [3], log-scales [3], rotation (w, x, y, z) [4], opacity logit; world) that
// the key frame did not list: does its ellipse reach a pixel of this camera (R, t world to
// camera)? Cheap bound first (may_reach_image), then the exact pipeline's own test.
CATGS_HD bool unlisted_reaches_image(const float* mean, const float* log_scale, const float* rotation,
                                     float opacity_logit, const glm::mat3& R, glm::vec3 t, float fx, float fy,
                                     float cx, float cy, float near_plane, float far_plane, glm::vec2 tan_half_fov,
                                     int width, int height) {
  const float q_max = opacity_aware_qmax(sigmoid(opacity_logit));
  if (!(q_max > 0.0f)) return false;
  const glm::vec3 m(mean[0], mean[1], mean[2]);
  const glm::vec3 p = R * m + t;
  if (!(p.z > near_plane) || p.z > far_plane) return false;
  const float max_scale = max_scale_of(log_scale);
  if (!may_reach_image(p, max_scale, q_max, fx, fy, cx, cy, tan_half_fov, width, height)) return false;
  const glm::vec3 cov2 = covariance_2d(covariance_3d({log_scale[0], log_scale[1], log_scale[2]},
                                                     {rotation[0], rotation[1], rotation[2], rotation[3]}),
                                       R, p, fx, fy, tan_half_fov);
  glm::vec3 conic;
  if (!conic_from_cov2d(cov2, &conic)) return false;
  const glm::vec2 mean2d(fx * p.x / p.z + cx - 0.5f, fy * p.y / p.z + cy - 0.5f);
  return ellipse_reaches_image(mean2d, cov2, conic, q_max, width, height);
}

}  // namespace catgs::fm

namespace catgs::fm {

// A Gaussian's trail over a speculation window (DESIGN.md 1): its ellipse (covariance `cov`,
// level q_trail) swept from mean0 along `motion`, all in pixel units.
struct Trail {
  glm::vec2 mean0;
  glm::vec2 motion;
  glm::vec3 cov;
  float q_trail;
};

// Builds the trail that holds the Gaussian's ellipse (level q_max) at each of n >= 1 sampled
// poses of the predicted path (means[k], covs[k]; the first is the key frame, the last the end of
// the window): the covariance dominates every sample's, and the level is the least for which
// trail_contains() accepts every sample, widened so that poses between and near the samples are
// held too: + margin_px + motion_margin * |motion| pixels along the trail's narrowest axis
// (prediction error does not shrink with the Gaussian, and grows with how far the prediction
// carries it: an error in the camera's velocity moves each Gaussian in proportion to its own
// screen motion), then scaled by (1 + slack).
CATGS_HD Trail build_trail(const glm::vec2* means, const glm::vec3* covs, int n, float q_max,
                           float slack, float margin_px = 0.0f, float motion_margin = 0.0f) {
  Trail t{means[0], means[n - 1] - means[0], covs[0], q_max};
  margin_px += motion_margin * sqrtf(t.motion.x * t.motion.x + t.motion.y * t.motion.y);
  for (int k = 1; k < n; ++k) t.cov = dominating_cov2d(t.cov, covs[k]);
  glm::vec3 conic;
  if (!conic_from_cov2d(t.cov, &conic)) return t;
  const float det_u = t.cov.x * t.cov.z - t.cov.y * t.cov.y;
  float level = 0.0f;
  for (int k = 0; k < n; ++k) {
    const glm::vec3 a = covs[k];
    const float det_a = a.x * a.z - a.y * a.y;
    const float bq = a.x * t.cov.z + a.z * t.cov.x - 2.0f * a.y * t.cov.y;
    const float lambda = (bq + sqrtf(fmaxf(0.0f, bq * bq - 4.0f * det_u * det_a))) / (2.0f * det_u);
    const float off = min_quadratic_on_segment(conic, means[k] - t.mean0, means[k] - t.mean0 - t.motion);
    level = fmaxf(level, sqrtf(fmaxf(0.0f, lambda) * q_max) + sqrtf(off));
  }
  // An offset of margin_px costs at most margin_px / sqrt(smallest eigenvalue) of the level.
  const float mid = 0.5f * (t.cov.x + t.cov.z);
  const float lambda_min = mid - sqrtf(fmaxf(0.0f, mid * mid - det_u));
  if (margin_px > 0.0f && lambda_min > 0.0f) level += margin_px / sqrtf(lambda_min);
  level *= 1.0f + slack;
  t.q_trail = level * level;
  return t;
}

}  // namespace catgs::fm
