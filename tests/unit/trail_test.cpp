// Speculative pre-processing: the trail test is conservative (never misses a tile that the
// Gaussian's ellipse touches at any of 64 poses along the predicted path) and reports how tight it is.
#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "camera/camera.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/chunk_bounds.h"
#include "forward_model/forward_model.h"
#include "forward_model/trail.h"

namespace catgs {
namespace {

struct Projected {
  bool visible;
  glm::vec2 mean;
  glm::vec3 cov;
};

Projected project(const Camera& c, glm::vec3 mean, const fm::Cov3& S) {
  const glm::vec3 p = c.R * mean + c.t;
  if (!(p.z > c.near_plane)) return {false, {}, {}};
  const glm::vec2 tan_half(static_cast<float>(c.width) / (2.0f * c.fx), static_cast<float>(c.height) / (2.0f * c.fy));
  return {true,
          {c.fx * p.x / p.z + c.cx - 0.5f, c.fy * p.y / p.z + c.cy - 0.5f},
          fm::covariance_2d(S, c.R, p, c.fx, c.fy, tan_half)};
}

Camera pose_between(const glm::vec3& p0, const glm::quat& q0, const glm::vec3& p1, const glm::quat& q1, float fov0,
                    float fov1, float s) {
  return Camera::from_pose(p0 + s * (p1 - p0), glm::slerp(q0, q1, s), fov0 + s * (fov1 - fov0), 320, 240);
}

TEST(TrailTest, HoldsEveryTileAlongThePredictedPath) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), u01(0.0f, 1.0f);
  std::size_t trail_tiles = 0, needed_tiles = 0, key_tiles = 0, gaussians = 0;
  for (int motion = 0; motion < 40; ++motion) {
    // A camera path of one speculation window: translation, rotation and zoom (fov change).
    const glm::vec3 p0(u(rng), u(rng), -4.0f + u(rng));
    const glm::quat q0 = glm::normalize(glm::quat(1.0f, 0.05f * u(rng), 0.05f * u(rng), 0.05f * u(rng)));
    const float scale = motion < 10 ? 0.02f : 0.15f;  // slow and fast windows
    const glm::vec3 p1 = p0 + scale * glm::vec3(u(rng), u(rng), u(rng));
    const glm::quat q1 = glm::normalize(q0 * glm::quat(1.0f, scale * u(rng), scale * u(rng), scale * u(rng)));
    const float fov0 = 50.0f, fov1 = 50.0f + 10.0f * scale * u(rng);
    // The key frame samples the path at its W + 1 = 5 frame poses (k / W, k = 0..4).
    Camera samples[5];
    for (int k = 0; k < 5; ++k) samples[k] = pose_between(p0, q0, p1, q1, fov0, fov1, static_cast<float>(k) / 4.0f);
    for (int g = 0; g < 150; ++g) {
      const glm::vec3 mean(1.5f * u(rng), 1.5f * u(rng), 1.5f * u(rng));
      const glm::vec3 log_scale(-4.0f + 2.5f * u01(rng), -4.0f + 2.5f * u01(rng), -4.0f + 2.5f * u01(rng));
      const glm::vec4 rot(u(rng), u(rng), u(rng), u(rng));
      const float opacity = 0.01f + 0.98f * u01(rng);
      const float q_max = fm::opacity_aware_qmax(opacity);
      const fm::Cov3 S = fm::covariance_3d(log_scale, rot);
      glm::vec2 means[5];
      glm::vec3 covs[5];
      bool visible = true;
      for (int k = 0; k < 5; ++k) {
        const Projected p = project(samples[k], mean, S);
        visible = visible && p.visible;
        means[k] = p.mean;
        covs[k] = p.cov;
      }
      if (!visible) continue;
      const fm::Trail trail = fm::build_trail(means, covs, 5, q_max, 0.1f);
      ++gaussians;
      // Tiles the trail lists.
      std::set<int> listed;
      const fm::TileRect r = fm::trail_tile_rect(trail.mean0, trail.motion, trail.cov, trail.q_trail, 320, 240);
      glm::vec3 conic;
      ASSERT_TRUE(fm::conic_from_cov2d(trail.cov, &conic));
      for (int ty = r.y0; ty < r.y1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx)
          if (fm::trail_touches_tile(trail.mean0, trail.motion, conic, trail.q_trail, tx, ty, 320, 240))
            listed.insert(ty * 20 + tx);
      // Tiles the ellipse really touches at 64 poses along the path.
      std::set<int> needed;
      for (int k = 0; k < 64; ++k) {
        const Projected p = project(pose_between(p0, q0, p1, q1, fov0, fov1, static_cast<float>(k) / 63.0f), mean, S);
        if (!p.visible) continue;
        glm::vec3 pc;
        ASSERT_TRUE(fm::conic_from_cov2d(p.cov, &pc));
        const fm::TileRect e = fm::ellipse_tile_rect(p.mean, p.cov, q_max, 320, 240);
        for (int ty = e.y0; ty < e.y1; ++ty)
          for (int tx = e.x0; tx < e.x1; ++tx)
            if (fm::ellipse_touches_tile(p.mean, pc, q_max, tx, ty, 320, 240)) {
              needed.insert(ty * 20 + tx);
              ASSERT_TRUE(listed.count(ty * 20 + tx)) << "window " << motion << " Gaussian " << g << " pose " << k
                                                      << " misses tile (" << tx << ", " << ty << ")";
              if (k == 0) ++key_tiles;
            }
        // The sub-frame check accepts every pose the trail was built for.
        if (k == 0 || k == 63) {
          EXPECT_TRUE(fm::trail_contains(trail.mean0, trail.motion, trail.cov, trail.q_trail, p.mean, p.cov, q_max));
        }
      }
      trail_tiles += listed.size();
      needed_tiles += needed.size();
    }
  }
  ASSERT_GT(gaussians, 1000u);
  std::cout << "[ info ] " << gaussians << " Gaussians: trail lists " << trail_tiles << " tiles, the 64 poses need "
            << needed_tiles << " (" << 100.0 * (double(trail_tiles) / double(needed_tiles) - 1.0)
            << "% extra), the key frame alone " << key_tiles << "\n";
  // Tight: in this harsh random setting (fast windows included) the trails list at most 50% more
  // tiles than the 64 poses need (conservativeness itself is asserted tile by tile above).
  EXPECT_LT(static_cast<double>(trail_tiles), 1.5 * static_cast<double>(needed_tiles));
}

// The stage itself (cpu::speculative_preprocess, which the CUDA core mirrors), with its cull of
// Gaussians beyond one image edge along the whole path and the motion-relative margin: on random
// Gaussians around and well outside the view, every tile an ellipse touches at 64 poses along the
// path is listed by the trail the stage built.
TEST(TrailTest, SpeculativePreprocessListsEveryTileAlongThePath) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), u01(0.0f, 1.0f);
  GaussianModel model;
  const std::size_t n = 3000;
  model.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Laterally up to 2.5x the half-width the view covers at this depth: most lie off the image.
    const float z = 1.0f + 3.0f * u01(rng);
    model.means[3 * i] = 2.5f * z * 0.47f * u(rng);
    model.means[3 * i + 1] = 2.5f * z * 0.35f * u(rng);
    model.means[3 * i + 2] = z;
    for (int a = 0; a < 3; ++a) model.log_scales[3 * i + a] = -4.5f + 3.0f * u01(rng);
    for (int a = 0; a < 4; ++a) model.rotations[4 * i + a] = u(rng);
    model.opacity_logits[i] = 4.0f * u(rng);
  }
  std::size_t listed_gaussians = 0, off_image = 0;
  for (int motion = 0; motion < 6; ++motion) {
    const glm::vec3 p0(0.1f * u(rng), 0.1f * u(rng), -0.5f);
    const glm::quat q0 = glm::normalize(glm::quat(1.0f, 0.02f * u(rng), 0.02f * u(rng), 0.02f * u(rng)));
    const float scale = motion < 2 ? 0.01f : 0.05f;
    const glm::vec3 p1 = p0 + scale * glm::vec3(u(rng), u(rng), u(rng));
    const glm::quat q1 = glm::normalize(q0 * glm::quat(1.0f, scale * u(rng), scale * u(rng), scale * u(rng)));
    std::vector<Camera> path;
    for (int k = 0; k < 5; ++k)
      path.push_back(pose_between(p0, q0, p1, q1, 50.0f, 50.0f, static_cast<float>(k) / 4.0f));
    cpu::ProjectedGaussians out;
    const TrailWidening widening{0.1f, 0.5f, motion % 2 == 0 ? 0.0f : 0.25f};
    cpu::speculative_preprocess(model, chunk_bounds_of(model), path, widening, out);
    for (std::size_t i = 0; i < n; ++i) {
      const glm::vec3 mean(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
      const fm::Cov3 S = fm::covariance_3d(
          {model.log_scales[3 * i], model.log_scales[3 * i + 1], model.log_scales[3 * i + 2]},
          {model.rotations[4 * i], model.rotations[4 * i + 1], model.rotations[4 * i + 2], model.rotations[4 * i + 3]});
      const float q_max = fm::opacity_aware_qmax(fm::sigmoid(model.opacity_logits[i]));
      if (!(q_max > 0.0f) || !project(path[0], mean, S).visible) continue;
      bool reaches = false;
      for (int k = 0; k < 64; ++k) {
        const Projected p = project(pose_between(p0, q0, p1, q1, 50.0f, 50.0f, static_cast<float>(k) / 63.0f), mean, S);
        glm::vec3 pc;
        if (!p.visible || !fm::conic_from_cov2d(p.cov, &pc)) continue;
        const fm::TileRect e = fm::ellipse_tile_rect(p.mean, p.cov, q_max, 320, 240);
        for (int ty = e.y0; ty < e.y1; ++ty)
          for (int tx = e.x0; tx < e.x1; ++tx) {
            if (!fm::ellipse_touches_tile(p.mean, pc, q_max, tx, ty, 320, 240)) continue;
            reaches = true;
            ASSERT_GT(out.tiles_touched[i], 0u) << "window " << motion << " Gaussian " << i << " pose " << k;
            ASSERT_TRUE(fm::trail_touches_tile(out.trail_mean0[i], out.trail_motion[i], out.trail_conic[i],
                                               out.q_trail[i], tx, ty, 320, 240))
                << "window " << motion << " Gaussian " << i << " pose " << k << " misses tile (" << tx << ", " << ty
                << ")";
          }
      }
      listed_gaussians += out.tiles_touched[i] > 0 ? 1 : 0;
      off_image += reaches ? 0 : 1;
    }
  }
  std::cout << "[ info ] listed " << listed_gaussians << " Gaussian-windows; " << off_image
            << " in front of the key camera never reach the image\n";
  EXPECT_GT(listed_gaussians, 1000u);
  EXPECT_GT(off_image, 1000u);  // many Gaussians the path cull may drop, none of them wrongly
}

// fm::edges_beyond, the bound behind that cull: which edges a Gaussian lies beyond.
TEST(TrailTest, EdgesBeyondNamesTheEdge) {
  const glm::vec2 tan_half(320.0f / (2.0f * 300.0f), 240.0f / (2.0f * 300.0f));
  const fm::View view{glm::mat3(1.0f), glm::vec3(0.0f), 300.0f, 300.0f, 160.0f, 120.0f, 320, 240, 0.2f,
                      1000.0f,         tan_half};
  auto edges = [&](glm::vec3 p, float widen, float extra) {
    return fm::edges_beyond(p, 0.01f, 9.0f, view, widen, extra);
  };
  EXPECT_EQ(edges({0.0f, 0.0f, 2.0f}, 1.0f, 0.0f), 0u);       // centre of the view
  EXPECT_EQ(edges({-3.0f, 0.0f, 2.0f}, 1.0f, 0.0f), 1u);      // far left
  EXPECT_EQ(edges({3.0f, 3.0f, 2.0f}, 1.0f, 0.0f), 2u | 8u);  // far right and below
  // Just beyond the left edge: u = -20.5 px, r = 3 * (0.01 * 230 + 0.55) + 1 ~ 9.6 px.
  const glm::vec3 near_left(-180.0f / 150.0f, 0.0f, 2.0f);
  EXPECT_EQ(edges(near_left, 1.0f, 0.0f), 1u);
  EXPECT_EQ(edges(near_left, 1.0f, 15.0f), 0u);  // widened past the edge: may reach the image
  EXPECT_EQ(edges(near_left, 3.0f, 0.0f), 0u);
  EXPECT_TRUE(fm::may_reach_image({0.0f, 0.0f, 2.0f}, 0.01f, 9.0f, view));
  EXPECT_FALSE(fm::may_reach_image(near_left, 0.01f, 9.0f, view));
}

// The motion-relative margin widens a moving Gaussian's trail and leaves a still one exact.
TEST(TrailTest, MotionMarginGrowsWithMotion) {
  const glm::vec3 covs[2] = {{4.0f, 0.5f, 3.0f}, {4.0f, 0.5f, 3.0f}};
  const float q_max = fm::opacity_aware_qmax(0.8f);
  const glm::vec2 still[2] = {{50.0f, 60.0f}, {50.0f, 60.0f}};
  EXPECT_EQ(fm::build_trail(still, covs, 2, q_max, 0.0f, 0.0f, 0.5f).q_trail,
            fm::build_trail(still, covs, 2, q_max, 0.0f, 0.0f, 0.0f).q_trail);
  const glm::vec2 slow[2] = {{50.0f, 60.0f}, {54.0f, 60.0f}}, fast[2] = {{50.0f, 60.0f}, {90.0f, 60.0f}};
  const float plain = fm::build_trail(fast, covs, 2, q_max, 0.0f).q_trail;
  const float slow_q = fm::build_trail(slow, covs, 2, q_max, 0.0f, 0.0f, 0.25f).q_trail;
  const float fast_q = fm::build_trail(fast, covs, 2, q_max, 0.0f, 0.0f, 0.25f).q_trail;
  EXPECT_GT(fast_q, plain);
  EXPECT_GT(fast_q, slow_q);
  // 0.25 * 40 px = 10 px along the narrowest axis: the level grows by 10 / sqrt(lambda_min).
  const float lambda_min = 3.5f - std::sqrt(0.25f + 0.25f);
  EXPECT_NEAR(std::sqrt(fast_q) - std::sqrt(plain), 10.0f / std::sqrt(lambda_min), 1e-3f);
}

// fm::min_quadratic_over_swept_rect walks only the hexagon's 6 boundary segments, in closed form:
// on random conics, rectangles and sweeps it must find the minimum over all 12 candidate segments
// (the rectangle's edges at s = 0 and s = 1 and all four corner sweeps, each minimised by
// fm::min_quadratic_on_segment), and 0 with the origin inside.
TEST(TrailTest, SweptRectMinimumUsesTheBoundaryOnly) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), u01(0.0f, 1.0f);
  int outside = 0;
  for (int n = 0; n < 20000; ++n) {
    const float a = 0.01f + u01(rng), c = 0.01f + u01(rng);
    const glm::vec3 conic(a, 0.95f * std::sqrt(a * c) * u(rng), c);  // positive definite
    const float x0 = 40.0f * u(rng), y0 = 40.0f * u(rng);
    const float x1 = x0 + 15.0f, y1 = y0 + 15.0f;
    // Sweeps of every direction, axis-parallel and zero ones included.
    glm::vec2 m(60.0f * u(rng), 60.0f * u(rng));
    if (n % 10 == 1) m.x = 0.0f;
    if (n % 10 == 2) m.y = 0.0f;
    if (n % 100 == 3) m = glm::vec2(0.0f);
    const float got =
        fm::min_quadratic_over_swept_rect(fm::make_trail_tile_test({0, 0}, m, conic, 0.0f), x0, x1, y0, y1);
    const glm::vec2 cs[4] = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
    float all = INFINITY;
    for (int k = 0; k < 4; ++k) {
      const glm::vec2 p = cs[k], q = cs[(k + 1) % 4];
      all = std::min({all, fm::min_quadratic_on_segment(conic, p, q), fm::min_quadratic_on_segment(conic, p - m, q - m),
                      fm::min_quadratic_on_segment(conic, p, p - m)});
    }
    if (got == 0.0f) continue;  // origin inside: checked below by sampling
    ++outside;
    ASSERT_NEAR(got, all, 1e-4f * std::max(1.0f, all)) << "case " << n;
  }
  EXPECT_GT(outside, 10000);
  // Origin inside the swept shape: 0.
  EXPECT_EQ(
      fm::min_quadratic_over_swept_rect(fm::make_trail_tile_test({0, 0}, {30, 4}, {1, 0, 1}, 0.0f), 5, 20, -3, 12),
      0.0f);  // s = 0.5 holds it
}

TEST(TrailTest, StillCameraTrailIsTheExactEllipse) {
  const glm::vec2 means[2] = {{100.3f, 50.7f}, {100.3f, 50.7f}};
  const glm::vec3 covs[2] = {{30.0f, 5.0f, 12.0f}, {30.0f, 5.0f, 12.0f}};
  const float q_max = fm::opacity_aware_qmax(0.7f);
  const fm::Trail t = fm::build_trail(means, covs, 2, q_max, 0.0f);
  EXPECT_NEAR(t.q_trail, q_max, 1e-3f * q_max);
  EXPECT_EQ(t.motion, glm::vec2(0.0f));
  glm::vec3 conic;
  ASSERT_TRUE(fm::conic_from_cov2d(covs[0], &conic));
  for (int ty = 0; ty < 15; ++ty)
    for (int tx = 0; tx < 20; ++tx)
      EXPECT_EQ(fm::trail_touches_tile(t.mean0, t.motion, conic, t.q_trail, tx, ty, 320, 240),
                fm::ellipse_touches_tile(means[0], conic, q_max, tx, ty, 320, 240));
}

TEST(TrailTest, ContainmentRejectsAnEllipseOffThePath) {
  const glm::vec2 means[2] = {{100.0f, 100.0f}, {140.0f, 100.0f}};
  const glm::vec3 covs[2] = {{10.0f, 0.0f, 10.0f}, {10.0f, 0.0f, 10.0f}};
  const float q_max = fm::opacity_aware_qmax(0.5f);
  const fm::Trail t = fm::build_trail(means, covs, 2, q_max, 0.1f);
  EXPECT_TRUE(fm::trail_contains(t.mean0, t.motion, t.cov, t.q_trail, {120.0f, 100.5f}, covs[0], q_max));
  EXPECT_FALSE(fm::trail_contains(t.mean0, t.motion, t.cov, t.q_trail, {120.0f, 115.0f}, covs[0], q_max));
  EXPECT_FALSE(fm::trail_contains(t.mean0, t.motion, t.cov, t.q_trail, {120.0f, 100.0f}, {40.0f, 0.0f, 10.0f}, q_max));
}

}  // namespace
}  // namespace catgs
