// Chunk culling (forward_model/chunk_bounds.h): a culled chunk holds no Gaussian the exact
// pipeline would list, so pre-processing with and without it gives the same tiles; checked on
// real scenes from inside and outside, and against the per-Gaussian decision on random chunks
// that straddle the image's edges and the near plane.
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/chunk_bounds.h"
#include "test_data.h"

namespace catgs {
namespace {

// Bounds that never cull (NaN boxes): pre-processing Gaussian by Gaussian.
std::vector<fm::ChunkBounds> never_cull(std::size_t n) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  return std::vector<fm::ChunkBounds>(fm::chunk_count(n), fm::ChunkBounds{glm::vec3(nan), nan, glm::vec3(nan), nan});
}

// Views of `m`: an orbit outside it looking in, and poses inside it looking outwards.
std::vector<Camera> views_of(const GaussianModel& m, int width, int height) {
  GeneratorParams p;
  p.width = width;
  p.height = height;
  p.duration_s = 1.0;
  p.rate_hz = 8.0;
  const Bounds b = m.bounds();
  std::vector<Camera> views;
  for (const auto& tc : make_orbit(b, 0.6f * glm::length(b.extent()), 0.1f * glm::length(b.extent()), 360.0f, p))
    views.push_back(tc.camera);
  const glm::vec3 centre = 0.5f * (b.min + b.max);
  for (int k = 0; k < 6; ++k) {
    const float yaw = glm::radians(60.0f * static_cast<float>(k));
    const glm::quat q = glm::angleAxis(yaw, glm::vec3(0.0f, 1.0f, 0.0f));
    views.push_back(Camera::from_pose(centre, q, 50.0f, width, height));
  }
  return views;
}

struct Counts {
  std::size_t culled = 0, chunks = 0;
};

// Pre-processes `m` at every view with and without chunk culling and expects the same tile
// counts; returns how many chunks the views culled.
Counts expect_same_tiles(const GaussianModel& m) {
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(m), none = never_cull(m.size());
  Counts c;
  for (const Camera& cam : views_of(m, 320, 180)) {
    cpu::ProjectedGaussians culled, full;
    cpu::preprocess(m, chunks, cam, Pipeline::exact, culled);
    cpu::preprocess(m, none, cam, Pipeline::exact, full);
    EXPECT_EQ(culled.tiles_touched, full.tiles_touched);
    const fm::View v = fm::view_of(cam);
    for (const fm::ChunkBounds& b : chunks) c.culled += fm::chunk_outside_view(b, v) ? 1 : 0;
    c.chunks += chunks.size();
  }
  return c;
}

TEST(ChunkCulling, SameTilesOnTheBundledScene) {
  const Counts c = expect_same_tiles(*test::cached_scene(test::bundled_scene()));
  EXPECT_GT(c.culled, c.chunks / 10) << "the views should leave a good share of the chunks outside";
}

TEST(ChunkCulling, SameTilesOnFlowers) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const Counts c = expect_same_tiles(*test::cached_scene(path));
  EXPECT_GT(c.culled, 0u);
}

// Fills `m` with one chunk of Gaussians in a random box centred near the frustum's side planes
// (tan_half_fov_x of the view) at depth 0.05..20 (behind the camera with `behind_share`), up to
// 1 unit wide, with random scales, rotations and opacities.
void random_chunk(GaussianModel& m, std::size_t per_chunk, float tan_half_fov_x, float behind_share,
                  std::mt19937& rng) {
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const float z = 0.05f + 20.0f * u01(rng) * u01(rng);
  const float side = (u01(rng) < 0.5f ? -1.0f : 1.0f) * (0.5f + u01(rng)) * tan_half_fov_x * z;
  const glm::vec3 centre(u01(rng) < 0.5f ? side : 0.3f * side, u01(rng) < 0.5f ? side * 0.56f : 0.0f,
                         u01(rng) < behind_share ? -z : z);
  const glm::vec3 half = glm::vec3(u01(rng), u01(rng), u01(rng)) * (u01(rng) < 0.5f ? 0.05f : 1.0f);
  const float log_scale = std::log(0.001f + 0.2f * u01(rng) * u01(rng));
  m.sh_degree = 0;
  m.resize(per_chunk);
  for (std::size_t i = 0; i < per_chunk; ++i) {
    for (int a = 0; a < 3; ++a) {
      m.means[3 * i + a] = centre[a] + half[a] * (2.0f * u01(rng) - 1.0f);
      m.log_scales[3 * i + a] = log_scale - 2.0f * u01(rng);
    }
    glm::vec4 q(u01(rng) - 0.5f, u01(rng) - 0.5f, u01(rng) - 0.5f, u01(rng) - 0.5f);
    q /= glm::length(q);
    for (int a = 0; a < 4; ++a) m.rotations[4 * i + a] = q[a];
    m.opacity_logits[i] = 8.0f * u01(rng) - 2.0f;
  }
}

// Random chunks around the view's edges, the near plane and the far plane: whenever the chunk
// test culls, every Gaussian drawn inside the chunk's bound is culled Gaussian by Gaussian.
TEST(ChunkCulling, NeverCullsAListedGaussian) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const Camera cam = Camera::from_pose(glm::vec3(0.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 160, 90);
  const fm::View v = fm::view_of(cam);
  GaussianModel m;
  m.sh_degree = 0;
  const std::size_t per_chunk = 64;
  std::size_t culled_chunks = 0, checked = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    random_chunk(m, per_chunk, v.tan_half_fov.x, 0.0f, rng);
    const std::vector<fm::ChunkBounds> b = chunk_bounds_of(m);
    ASSERT_EQ(b.size(), 1u);
    if (!fm::chunk_outside_view(b[0], v)) continue;
    ++culled_chunks;
    cpu::ProjectedGaussians full;
    cpu::preprocess(m, never_cull(per_chunk), cam, Pipeline::exact, full);
    for (std::size_t i = 0; i < per_chunk; ++i, ++checked)
      ASSERT_EQ(full.tiles_touched[i], 0u) << "trial " << trial << ": chunk culled, Gaussian " << i << " lists tiles";
  }
  EXPECT_GT(culled_chunks, 300u) << "too few culled chunks to say much";
  EXPECT_GT(checked, 0u);
}

// The catgs key frame's form (fm::chunk_misses_path): speculative pre-processing over a path
// of 3 poses gives the same tiles with and without it, on real scenes; returns the chunks culled.
Counts expect_same_trail_tiles(const GaussianModel& m) {
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(m), none = never_cull(m.size());
  const std::vector<Camera> views = views_of(m, 320, 180);
  const TrailWidening widening{0.1f, 0.5f, 0.25f};
  Counts c;
  for (std::size_t k = 0; k + 3 <= views.size(); k += 3) {
    // Three consecutive views: orbit steps, or turns in place from the centre.
    const std::vector<Camera> path(views.begin() + static_cast<std::ptrdiff_t>(k),
                                   views.begin() + static_cast<std::ptrdiff_t>(k + 3));
    cpu::ProjectedGaussians culled, full;
    cpu::speculative_preprocess(m, chunks, path, widening, culled);
    cpu::speculative_preprocess(m, none, path, widening, full);
    EXPECT_EQ(culled.tiles_touched, full.tiles_touched) << "path from view " << k;
    std::vector<fm::View> v;
    for (const Camera& cam : path) v.push_back(fm::view_of(cam));
    const auto view_at = [&](int j) -> const fm::View& { return v[static_cast<std::size_t>(j)]; };
    for (const fm::ChunkBounds& b : chunks)
      c.culled += fm::chunk_misses_path(b, static_cast<int>(v.size()), view_at, 1.1f, 0.5f, 0.25f) ? 1 : 0;
    c.chunks += chunks.size();
  }
  return c;
}

TEST(ChunkCulling, SameTrailTilesOnTheBundledScene) {
  const Counts c = expect_same_trail_tiles(*test::cached_scene(test::bundled_scene()));
  EXPECT_GT(c.culled, c.chunks / 20) << "the paths should leave some chunks outside";
}

TEST(ChunkCulling, SameTrailTilesOnFlowers) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const Counts c = expect_same_trail_tiles(*test::cached_scene(path));
  EXPECT_GT(c.culled, 0u);
}

// Random chunks near the frustum's sides and a path that turns and moves the camera: whenever
// the path test culls, the per-Gaussian speculative pre-processing lists none of the chunk's
// Gaussians.
TEST(ChunkCulling, PathTestNeverCullsAListedGaussian) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  GaussianModel m;
  m.sh_degree = 0;
  const std::size_t per_chunk = 64;
  const TrailWidening widening{0.1f, 0.5f, 0.25f};
  std::size_t culled_chunks = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const float yaw = glm::radians(20.0f * (u01(rng) - 0.5f));
    const glm::vec3 move(0.5f * (u01(rng) - 0.5f), 0.2f * (u01(rng) - 0.5f), 0.5f * (u01(rng) - 0.5f));
    std::vector<Camera> path;
    for (int k = 0; k < 4; ++k) {
      const float t = static_cast<float>(k) / 3.0f;
      path.push_back(Camera::from_pose(t * move, glm::angleAxis(t * yaw, glm::vec3(0.0f, 1.0f, 0.0f)), 60.0f, 160, 90));
    }
    random_chunk(m, per_chunk, fm::view_of(path[0]).tan_half_fov.x, 0.2f, rng);
    const std::vector<fm::ChunkBounds> b = chunk_bounds_of(m);
    std::vector<fm::View> v;
    for (const Camera& cam : path) v.push_back(fm::view_of(cam));
    const auto view_at = [&](int j) -> const fm::View& { return v[static_cast<std::size_t>(j)]; };
    if (!fm::chunk_misses_path(b[0], 4, view_at, 1.0f + widening.slack, widening.margin_px, widening.motion_margin))
      continue;
    ++culled_chunks;
    cpu::ProjectedGaussians full;
    cpu::speculative_preprocess(m, never_cull(per_chunk), path, widening, full);
    for (std::size_t i = 0; i < per_chunk; ++i)
      ASSERT_EQ(full.tiles_touched[i], 0u) << "trial " << trial << ": chunk culled, Gaussian " << i << " lists tiles";
  }
  EXPECT_GT(culled_chunks, 200u) << "too few culled chunks to say much";
}

// M (cpu::max_screen_motion), the speculation planner's input, skips chunks none of whose means
// can count (fm::chunk_means_off_image): the same M as Gaussian by Gaussian (NaN bounds skip
// nothing), on real scenes, for consecutive views and three depth thresholds; returns the
// chunks skipped.
Counts expect_same_motion(const GaussianModel& m) {
  const std::vector<fm::ChunkBounds> chunks = chunk_bounds_of(m), none = never_cull(m.size());
  const std::vector<Camera> views = views_of(m, 320, 180);
  Counts c;
  for (std::size_t k = 0; k + 1 < views.size(); ++k)
    for (float min_depth : {0.05f, 0.4f, 2.0f}) {
      const float skipping = cpu::max_screen_motion(m, chunks, views[k], views[k + 1], min_depth);
      const float every = cpu::max_screen_motion(m, none, views[k], views[k + 1], min_depth);
      EXPECT_EQ(skipping, every) << "view " << k << ", min_depth " << min_depth;
      for (const fm::ChunkBounds& b : chunks)
        c.culled += fm::chunk_means_off_image(b, fm::view_of(views[k]), min_depth) ? 1 : 0;
      c.chunks += chunks.size();
    }
  return c;
}

TEST(ChunkCulling, SameMotionOnTheBundledScene) {
  const Counts c = expect_same_motion(*test::cached_scene(test::bundled_scene()));
  EXPECT_GT(c.culled, c.chunks / 10) << "the views should leave a good share of the chunks off the image";
}

TEST(ChunkCulling, SameMotionOnFlowers) {
  CATGS_REQUIRE_DATA(path, "scenes/flowers_sh3.ply");
  const Counts c = expect_same_motion(*test::cached_scene(path));
  EXPECT_GT(c.culled, 0u);
}

// Random chunks around the view's edges, in front and behind: whenever M's chunk test skips,
// no mean drawn inside the chunk counts for M (deeper than min_depth, centre on the image).
TEST(ChunkCulling, MotionSkipNeverDropsACountingMean) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const Camera cam = Camera::from_pose(glm::vec3(0.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 160, 90);
  const fm::View v = fm::view_of(cam);
  GaussianModel m;
  const std::size_t per_chunk = 64;
  std::size_t skipped = 0, kept = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    random_chunk(m, per_chunk, v.tan_half_fov.x, 0.2f, rng);
    const float min_depth = 0.02f + 3.0f * u01(rng) * u01(rng);
    if (!fm::chunk_means_off_image(chunk_bounds_of(m)[0], v, min_depth)) {
      ++kept;
      continue;
    }
    ++skipped;
    for (std::size_t i = 0; i < per_chunk; ++i) {
      const glm::vec3 x(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
      const glm::vec3 p = cam.R * x + cam.t;
      if (!(p.z > min_depth)) continue;
      const float u = cam.fx * p.x / p.z + cam.cx, w = cam.fy * p.y / p.z + cam.cy;
      ASSERT_FALSE(u >= 0 && w >= 0 && u <= static_cast<float>(cam.width) && w <= static_cast<float>(cam.height))
          << "trial " << trial << ": chunk skipped, mean " << i << " lies on the image at depth " << p.z;
    }
  }
  EXPECT_GT(skipped, 300u) << "too few skipped chunks to say much";
  EXPECT_GT(kept, 300u);
}

TEST(ChunkCulling, NonFiniteBoundsNeverCull) {
  const Camera cam = Camera::from_pose(glm::vec3(0.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 160, 90);
  const fm::View v = fm::view_of(cam);
  // Behind the camera, so finite bounds would cull it.
  fm::ChunkBounds b{glm::vec3(-1.0f, -1.0f, -5.0f), 0.1f, glm::vec3(1.0f, 1.0f, -4.0f), 10.0f};
  EXPECT_TRUE(fm::chunk_outside_view(b, v));
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    fm::ChunkBounds c = b;
    c.lo.x = bad;
    EXPECT_FALSE(fm::chunk_outside_view(c, v));
    c = b;
    c.max_scale = bad;
    EXPECT_FALSE(fm::chunk_outside_view(c, v));
  }
}

}  // namespace
}  // namespace catgs
