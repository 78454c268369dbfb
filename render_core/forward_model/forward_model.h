// The forward model of 3DGS, shared by the CPU reference and the CUDA core so both compute the same
// numbers (docs/DESIGN.md "Forward model"; Kerbl et al. 2023, EWA splatting, Zwicker et al. 2001).
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

#include "camera/camera.h"

#if defined(__CUDACC__)
#define CATGS_HD __host__ __device__ __forceinline__
#else
#define CATGS_HD inline
#endif

namespace catgs::fm {

inline constexpr int kTileSize = 16;               // tiles of 16 x 16 pixels
inline constexpr float kMinAlpha = 1.0f / 255.0f;  // alpha below this is skipped
inline constexpr float kMaxAlpha = 0.99f;          // alpha is clamped to this
inline constexpr float kMinTransmittance = 1e-4f;  // a pixel stops before T would drop below
inline constexpr float kLowPass = 0.3f;            // px^2 added to the 2D covariance diagonal
inline constexpr float kFrustumClamp = 1.3f;       // Jacobian clamped to 1.3x the fov
// The exact tile test includes tiles whose best pixel has q slightly above the alpha threshold, so
// float rounding in exp() can never drop a pixel the rasterizer would blend.
inline constexpr float kExactQMargin = 1e-3f;

// A camera as the per-Gaussian maths reads it (the CPU reference builds it from a Camera with
// view_of(); the CUDA kernels' stages::CameraParams extends it): world-to-camera R, t (OpenCV
// axes); intrinsics in pixels, (cx, cy) in continuous image coordinates; image size in pixels;
// near and far planes in camera-space z, world units; tan_half_fov = (W / (2 fx), H / (2 fy)).
struct View {
  glm::mat3 R;
  glm::vec3 t;
  float fx, fy, cx, cy;
  int width, height;
  float near_plane, far_plane;
  glm::vec2 tan_half_fov;
};

// Rotation matrix (row-major maths, returned as glm column-major) of quaternion (w, x, y, z).
CATGS_HD glm::mat3 quat_to_mat(glm::vec4 q) {
  const float n = sqrtf(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  q = n > 0.0f ? q / n : glm::vec4(1.0f, 0.0f, 0.0f, 0.0f);
  const float w = q.x, x = q.y, y = q.z, z = q.w;
  // glm::mat3(c0, c1, c2) takes columns.
  return glm::mat3(1.f - 2.f * (y * y + z * z), 2.f * (x * y + w * z), 2.f * (x * z - w * y), 2.f * (x * y - w * z),
                   1.f - 2.f * (x * x + z * z), 2.f * (y * z + w * x), 2.f * (x * z + w * y), 2.f * (y * z - w * x),
                   1.f - 2.f * (x * x + y * y));
}

// World 3D covariance Sigma = R S S^T R^T from log-scales and a (w, x, y, z) quaternion;
// returned as its 6 unique entries (xx, xy, xz, yy, yz, zz).
struct Cov3 {
  float xx, xy, xz, yy, yz, zz;
};
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
CATGS_HD glm::vec3 covariance_2d(const Cov3& S, const glm::mat3& W, glm::vec3 p_cam, float fx, float fy,
                                 glm::vec2 tan_half_fov) {
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
// Returns false when the covariance is singular or not finite (a Gaussian whose scale overflows
// float: there is no ellipse to draw, and its NaN conic would reach the blend).
CATGS_HD bool conic_from_cov2d(glm::vec3 cov, glm::vec3* conic) {
  const float det = cov.x * cov.z - cov.y * cov.y;
  // det - det is 0 for every finite det and NaN for Inf or NaN (no isfinite needed on the device).
  if (det == 0.0f || !(det - det == 0.0f)) return false;
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
struct TileRect {
  int x0, y0, x1, y1;
};
CATGS_HD int tile_count(const TileRect& r) { return (r.x1 > r.x0 && r.y1 > r.y0) ? (r.x1 - r.x0) * (r.y1 - r.y0) : 0; }

// Every tile: the region of a frame drawn in one pass (clip_tile_rect leaves a rectangle as is).
inline constexpr TileRect kAllTiles{0, 0, 0x7fffffff, 0x7fffffff};

// `r` clipped to `region`: the tiles a Gaussian may list in one pass of a frame drawn in passes
// (renderer/render_passes.h). Its projection and tile tests stay the whole frame's (the camera,
// and so the Jacobian clamp at 1.3x the frame's field of view, is not cut), so the passes' lists
// together are the single pass's list. Empty (tile_count 0) where they do not meet.
CATGS_HD TileRect clip_tile_rect(const TileRect& r, const TileRect& region) {
  return {r.x0 > region.x0 ? r.x0 : region.x0, r.y0 > region.y0 ? r.y0 : region.y0, r.x1 < region.x1 ? r.x1 : region.x1,
          r.y1 < region.y1 ? r.y1 : region.y1};
}

// A tile coordinate clamped to [0, hi] in float before the conversion: a float outside int's range
// (an infinite radius, a mean far off screen) would make static_cast<int> undefined. NaN gives 0.
// Truncation toward zero, as the reference's int conversion, for every value inside the range.
CATGS_HD int clamp_tile_coord(float v, int hi) {
  if (!(v > 0.0f)) return 0;
  if (v >= static_cast<float>(hi)) return hi;
  return static_cast<int>(v);
}

// vanilla: the reference 3DGS getRect over a square of half-size `radius` around `mean`. An
// infinite radius covers the grid; a NaN mean or radius gives an empty rectangle.
CATGS_HD TileRect square_tile_rect(glm::vec2 mean, float radius, int grid_w, int grid_h) {
  return {clamp_tile_coord((mean.x - radius) / kTileSize, grid_w),
          clamp_tile_coord((mean.y - radius) / kTileSize, grid_h),
          clamp_tile_coord((mean.x + radius + kTileSize - 1) / kTileSize, grid_w),
          clamp_tile_coord((mean.y + radius + kTileSize - 1) / kTileSize, grid_h)};
}

// exact: q_max such that opacity * exp(-q / 2) >= 1/255 <=> q <= q_max = 2 ln(255 opacity).
// Negative when the Gaussian can never reach alpha 1/255 (cull it).
CATGS_HD float opacity_aware_qmax(float opacity) { return 2.0f * logf(255.0f * opacity); }

// exact: tiles holding pixel centres inside the ellipse q <= q_max (bounding box half-widths
// sqrt(q_max * cov_xx), sqrt(q_max * cov_yy)), clamped to the grid.
CATGS_HD TileRect ellipse_tile_rect(glm::vec2 mean, glm::vec3 cov, float q_max, int width, int height) {
  const float hx = sqrtf(q_max * cov.x), hy = sqrtf(q_max * cov.z);
  const float px0 = fmaxf(0.0f, ceilf(mean.x - hx)), py0 = fmaxf(0.0f, ceilf(mean.y - hy));
  const float px1 = fminf(static_cast<float>(width - 1), floorf(mean.x + hx));
  const float py1 = fminf(static_cast<float>(height - 1), floorf(mean.y + hy));
  if (px1 < px0 || py1 < py0) return {0, 0, 0, 0};
  return {static_cast<int>(px0) / kTileSize, static_cast<int>(py0) / kTileSize, static_cast<int>(px1) / kTileSize + 1,
          static_cast<int>(py1) / kTileSize + 1};
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
CATGS_HD bool ellipse_touches_tile(glm::vec2 mean, glm::vec3 conic, float q_max, int tx, int ty, int width,
                                   int height) {
  const float x0 = static_cast<float>(tx * kTileSize);
  const float y0 = static_cast<float>(ty * kTileSize);
  const float x1 = fminf(x0 + (kTileSize - 1), static_cast<float>(width - 1));
  const float y1 = fminf(y0 + (kTileSize - 1), static_cast<float>(height - 1));
  return min_quadratic_over_rect(conic, x0 - mean.x, x1 - mean.x, y0 - mean.y, y1 - mean.y) <= q_max + kExactQMargin;
}

// View-dependent colour from SH of degree <= 3 at unit direction `dir` (camera centre -> mean),
// + 0.5, clamped at 0 (reference 3DGS computeColorFromSH). `coeff(j)` returns coefficient j of one
// Gaussian's K x 3 (coefficient-major) array as a float: the cores read SH stored in half
// precision (sh_storage.h), the float overload below reads floats.
template <class Coeffs>
CATGS_HD glm::vec3 sh_to_color_from(int degree, const Coeffs& coeff, glm::vec3 dir) {
  constexpr float C0 = 0.28209479177387814f;
  constexpr float C1 = 0.4886025119029199f;
  auto c = [&coeff](int k) { return glm::vec3(coeff(3 * k), coeff(3 * k + 1), coeff(3 * k + 2)); };
  glm::vec3 result = C0 * c(0);
  if (degree > 0) {
    const float x = dir.x, y = dir.y, z = dir.z;
    result = result - C1 * y * c(1) + C1 * z * c(2) - C1 * x * c(3);
    if (degree > 1) {
      const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
      result = result + 1.0925484305920792f * xy * c(4) + -1.0925484305920792f * yz * c(5) +
               0.31539156525252005f * (2.0f * zz - xx - yy) * c(6) + -1.0925484305920792f * xz * c(7) +
               0.5462742152960396f * (xx - yy) * c(8);
      if (degree > 2) {
        result = result + -0.5900435899266435f * y * (3.0f * xx - yy) * c(9) + 2.890611442640554f * xy * z * c(10) +
                 -0.4570457994644658f * y * (4.0f * zz - xx - yy) * c(11) +
                 0.3731763325901154f * z * (2.0f * zz - 3.0f * xx - 3.0f * yy) * c(12) +
                 -0.4570457994644658f * x * (4.0f * zz - xx - yy) * c(13) + 1.445305721320277f * z * (xx - yy) * c(14) +
                 -0.5900435899266435f * x * (xx - 3.0f * yy) * c(15);
      }
    }
  }
  result += 0.5f;
  return glm::max(result, glm::vec3(0.0f));
}

// sh_to_color_from over K * 3 floats at `sh` (full precision: tools and oracles).
CATGS_HD glm::vec3 sh_to_color(int degree, const float* sh, glm::vec3 dir) {
  return sh_to_color_from(
      degree, [sh](int j) { return sh[j]; }, dir);
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

// The View of a Camera (host only: Camera's helpers are not device code).
inline View view_of(const Camera& c) {
  return {c.R,
          c.t,
          c.fx,
          c.fy,
          c.cx,
          c.cy,
          c.width,
          c.height,
          c.near_plane,
          c.far_plane,
          glm::vec2(static_cast<float>(c.width) / (2.0f * c.fx), static_cast<float>(c.height) / (2.0f * c.fy))};
}

}  // namespace catgs::fm

namespace catgs::fm {

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
// its path (path_misses_image below).
CATGS_HD unsigned edges_beyond(glm::vec3 p_cam, float max_scale, float q_max, const View& v, float widen = 1.0f,
                               float extra_px = 0.0f) {
  const float z = p_cam.z;
  const float tx = fminf(kFrustumClamp * v.tan_half_fov.x, fabsf(p_cam.x / z));
  const float ty = fminf(kFrustumClamp * v.tan_half_fov.y, fabsf(p_cam.y / z));
  const float jf = sqrtf(v.fx * v.fx * (1.0f + tx * tx) + v.fy * v.fy * (1.0f + ty * ty)) / z;
  const float r = widen * (sqrtf(q_max) * (max_scale * jf + sqrtf(kLowPass)) + 1.0f) + extra_px;
  const float u = v.fx * p_cam.x / z + v.cx - 0.5f, w = v.fy * p_cam.y / z + v.cy - 0.5f;
  return (u + r < 0.0f ? 1u : 0u) | (u - r > static_cast<float>(v.width - 1) ? 2u : 0u) | (w + r < 0.0f ? 4u : 0u) |
         (w - r > static_cast<float>(v.height - 1) ? 8u : 0u);
}
CATGS_HD bool may_reach_image(glm::vec3 p_cam, float max_scale, float q_max, const View& v) {
  return edges_beyond(p_cam, max_scale, q_max, v) == 0u;
}

// Largest axis of a Gaussian, world units: exp of its largest log-scale.
CATGS_HD float max_scale_of(const float* log_scale) {
  return expf(fmaxf(log_scale[0], fmaxf(log_scale[1], log_scale[2])));
}

// The speculative pre-processing's cheap cull before any 2D covariance (cpu/ and
// cuda/speculative_preprocess): true when a Gaussian of centre `mean` (world) and log-scales
// `log_scale` [3], in front of the key view view_at(0), lies beyond one same image edge at every view
// view_at(0 .. count - 1) of the path where it is in front, by more than edges_beyond's bound
// widened as its trail would be: (1 + slack) times, + margin_px + 1 px, + motion_margin times its
// centre's motion on the image from the key view to the last. Its ellipse then reaches no pixel
// at any sampled pose, nor between them (the region beyond an edge is a half-plane). A Gaussian
// behind the key view is not culled here (the caller drops it after projecting).
// `view_at`: k -> const View& (the CPU core's fm::view_of of its path's cameras; CUDA's
// CameraParams are Views).
template <class ViewAt>
CATGS_HD bool path_misses_image(glm::vec3 mean, const float* log_scale, float q_max, int count, ViewAt view_at,
                                float slack, float margin_px, float motion_margin) {
  const View& key = view_at(0);
  const glm::vec3 p0 = key.R * mean + key.t;
  if (!(p0.z > key.near_plane) || p0.z > key.far_plane) return false;
  const View& last = view_at(count - 1);
  const glm::vec3 pw = last.R * mean + last.t;
  float extra = margin_px + 1.0f;
  if (pw.z > last.near_plane && pw.z <= last.far_plane) {
    const glm::vec2 u0(key.fx * p0.x / p0.z, key.fy * p0.y / p0.z);
    const glm::vec2 uw(last.fx * pw.x / pw.z + last.cx - key.cx, last.fy * pw.y / pw.z + last.cy - key.cy);
    extra += motion_margin * glm::length(uw - u0);
  }
  const float max_scale = max_scale_of(log_scale);  // after the key view's test, as it culls most
  unsigned beyond = 0xfu;
  for (int k = 0; k < count && beyond != 0u; ++k) {
    const View& c = view_at(k);
    const glm::vec3 p = c.R * mean + c.t;
    if (!(p.z > c.near_plane) || p.z > c.far_plane) continue;
    beyond &= edges_beyond(p, max_scale, q_max, c, 1.0f + slack, extra);
  }
  return beyond != 0u;
}

// A Gaussian (mean [3], log-scales [3], rotation (w, x, y, z) [4], opacity logit; world) that
// the key frame did not list: does its ellipse reach a pixel of view `v`? Cheap bound first
// (may_reach_image), then the exact pipeline's own test.
CATGS_HD bool unlisted_reaches_image(const float* mean, const float* log_scale, const float* rotation,
                                     float opacity_logit, const View& v) {
  const float q_max = opacity_aware_qmax(sigmoid(opacity_logit));
  if (!(q_max > 0.0f)) return false;
  const glm::vec3 m(mean[0], mean[1], mean[2]);
  const glm::vec3 p = v.R * m + v.t;
  if (!(p.z > v.near_plane) || p.z > v.far_plane) return false;
  const float max_scale = max_scale_of(log_scale);
  if (!may_reach_image(p, max_scale, q_max, v)) return false;
  const glm::vec3 cov2 = covariance_2d(
      covariance_3d({log_scale[0], log_scale[1], log_scale[2]}, {rotation[0], rotation[1], rotation[2], rotation[3]}),
      v.R, p, v.fx, v.fy, v.tan_half_fov);
  glm::vec3 conic;
  if (!conic_from_cov2d(cov2, &conic)) return false;
  const glm::vec2 mean2d(v.fx * p.x / p.z + v.cx - 0.5f, v.fy * p.y / p.z + v.cy - 0.5f);
  return ellipse_reaches_image(mean2d, cov2, conic, q_max, v.width, v.height);
}

}  // namespace catgs::fm
