// Gaussian trails (paper sec. 3.1 "Fine-grained Intersection Detection"; docs/DESIGN.md
// "Speculation" 1): the geometry a catgs key frame lists a Gaussian by, shared by the CPU reference
// and the CUDA core. A Gaussian's trail is the region its ellipse q <= q_trail sweeps when its
// centre moves along the segment mean0 -> mean0 + motion (pixel units). Plain float maths, host and
// device.
#pragma once

#include "forward_model/forward_model.h"

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

// A trail's tile test (docs/DESIGN.md "Speculation" 1) with its per-Gaussian constants worked out
// once: the key frame asks it for every tile of the trail's rectangle, so the divisions the
// minimisation needs are done here, not per tile. conic: the trail's inverse 2D covariance
// (positive definite); motion: mean0 -> end of the window, pixels; q_limit = q_trail +
// kExactQMargin.
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
  return min_quadratic_over_swept_rect(t, x0 - t.mean0.x, x1 - t.mean0.x, y0 - t.mean0.y, y1 - t.mean0.y) <= t.q_limit;
}

// The same, for a caller that asks about one tile (it pays the per-Gaussian divisions each time).
CATGS_HD bool trail_touches_tile(glm::vec2 mean0, glm::vec2 motion, glm::vec3 conic, float q_trail, int tx, int ty,
                                 int width, int height) {
  return trail_touches_tile(make_trail_tile_test(mean0, motion, conic, q_trail), tx, ty, width, height);
}

// Tiles of the bounding box of a trail: both end ellipses (cov = the trail's 2D covariance).
CATGS_HD TileRect trail_tile_rect(glm::vec2 mean0, glm::vec2 motion, glm::vec3 cov, float q_trail, int width,
                                  int height) {
  // The box of the swept shape: both end ellipses' boxes and all between (either end may lie
  // off screen while the path crosses it).
  const float hx = sqrtf(q_trail * cov.x), hy = sqrtf(q_trail * cov.z);
  const glm::vec2 lo = glm::min(mean0, mean0 + motion) - glm::vec2(hx, hy);
  const glm::vec2 hi = glm::max(mean0, mean0 + motion) + glm::vec2(hx, hy);
  const float px0 = fmaxf(0.0f, ceilf(lo.x)), py0 = fmaxf(0.0f, ceilf(lo.y));
  const float px1 = fminf(static_cast<float>(width - 1), floorf(hi.x));
  const float py1 = fminf(static_cast<float>(height - 1), floorf(hi.y));
  if (px1 < px0 || py1 < py0) return {0, 0, 0, 0};
  return {static_cast<int>(px0) / kTileSize, static_cast<int>(py0) / kTileSize, static_cast<int>(px1) / kTileSize + 1,
          static_cast<int>(py1) / kTileSize + 1};
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
CATGS_HD bool trail_contains(glm::vec2 mean0, glm::vec2 motion, glm::vec3 trail_cov, float q_trail, glm::vec2 mean,
                             glm::vec3 cov, float q_max) {
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
                                 glm::vec2 mean, glm::vec3 cov, glm::vec3 conic, float q_max, int width, int height) {
  const TileRect r = ellipse_tile_rect(mean, cov, q_max, width, height);
  for (int ty = r.y0; ty < r.y1; ++ty)
    for (int tx = r.x0; tx < r.x1; ++tx)
      if (ellipse_touches_tile(mean, conic, q_max, tx, ty, width, height) &&
          !trail_touches_tile(mean0, motion, trail_conic, q_trail, tx, ty, width, height))
        return false;
  return true;
}

}  // namespace catgs::fm

namespace catgs::fm {

// A Gaussian's trail over a speculation window (docs/DESIGN.md "Speculation" 1): its ellipse
// (covariance `cov`, level q_trail) swept from mean0 along `motion`, all in pixel units.
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
CATGS_HD Trail build_trail(const glm::vec2* means, const glm::vec3* covs, int n, float q_max, float slack,
                           float margin_px = 0.0f, float motion_margin = 0.0f) {
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
