// Speculative pre-processing: the trail test is conservative (never misses a tile that the
// Gaussian's ellipse touches at any of 64 poses along the predicted path) and reports how tight it is.
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "catgs/camera.h"
#include "catgs/forward_model.h"

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

Camera pose_between(const glm::vec3& p0, const glm::quat& q0, const glm::vec3& p1, const glm::quat& q1,
                    float fov0, float fov1, float s) {
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
              ASSERT_TRUE(listed.count(ty * 20 + tx))
                  << "window " << motion << " Gaussian " << g << " pose " << k << " misses tile (" << tx << ", " << ty << ")";
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
