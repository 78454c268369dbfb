// Occlusion culling from the last frame (forward_model/occlusion.h, issue 72): the chunk test on
// hand-made maps, and the CPU core's frames with it against the same frames drawn without it on
// a real city (the oracle: the unculled render of the same pose).
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "cpu/cpu_renderer.h"
#include "forward_model/occlusion.h"
#include "small_city.h"
#include "test_data.h"

namespace catgs {
namespace {

// A 320 x 180 camera at the origin looking down +z (identity pose).
fm::View test_view() {
  const Camera cam = Camera::from_pose(glm::vec3(0.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 320, 180);
  return fm::view_of(cam);
}

// A small chunk of Gaussians of scale `scale` around (x, y, z) in front of test_view().
fm::ChunkBounds chunk_at(float x, float y, float z, float half, float scale = 0.01f) {
  return {glm::vec3(x - half, y - half, z - half), scale, glm::vec3(x + half, y + half, z + half), 2.0f * std::log(255.0f)};
}

struct Map {
  std::vector<float> depth;
  fm::OcclusionMap map;
};
Map wall_at(float depth, float shift = 0.0f) {
  Map m;
  const fm::View v = test_view();
  m.map = fm::occlusion_map(nullptr, v, v);
  m.depth.assign(static_cast<std::size_t>(m.map.tiles_x) * m.map.tiles_y, depth);
  m.map.depth = m.depth.data();
  m.map.shift = shift;
  return m;
}

TEST(OcclusionCull, ChunkBehindAWallIsCulledOneInFrontOrOffTheImageIsNot) {
  Map m = wall_at(5.0f);
  EXPECT_TRUE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 10.0f, 0.2f), m.map));
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 4.0f, 0.2f), m.map));   // in front of the wall
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 5.2f, 0.2f), m.map));   // straddles it
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(12.0f, 0.0f, 10.0f, 0.2f), m.map)); // past the image's edge
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, -10.0f, 0.2f), m.map)); // behind the eye
  // A big Gaussian reaches past its box: widened beyond the image, it is drawn.
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 10.0f, 0.2f, 20.0f), m.map));
  // No map: nothing is culled.
  fm::OcclusionMap none;
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 10.0f, 0.2f), none));
  // One Gaussian: the box of its one mean.
  const float q = 2.0f * std::log(255.0f);
  EXPECT_TRUE(fm::gaussian_occluded(glm::vec3(0.5f, -0.3f, 10.0f), 0.01f, q, m.map));
  EXPECT_FALSE(fm::gaussian_occluded(glm::vec3(0.5f, -0.3f, 4.0f), 0.01f, q, m.map));
  EXPECT_FALSE(fm::gaussian_occluded(glm::vec3(0.5f, -0.3f, 10.0f), 20.0f, q, m.map));
  EXPECT_FALSE(fm::gaussian_occluded(glm::vec3(12.0f, 0.0f, 10.0f), 0.01f, q, m.map));
  EXPECT_FALSE(fm::gaussian_occluded(glm::vec3(0.0f, 0.0f, 10.0f), 0.01f, q, none));
  // It agrees with the chunk of that one mean.
  for (float z : {4.9f, 5.1f, 6.0f, 30.0f})
    EXPECT_EQ(fm::gaussian_occluded(glm::vec3(0.2f, 0.1f, z), 0.05f, q, m.map),
              fm::chunk_occluded(fm::ChunkBounds{glm::vec3(0.2f, 0.1f, z), 0.05f, glm::vec3(0.2f, 0.1f, z), q}, m.map))
        << z;
}

TEST(OcclusionCull, OneUnsaturatedOrNanTileUnderTheChunkKeepsIt) {
  Map m = wall_at(5.0f);
  const fm::ChunkBounds c = chunk_at(0.0f, 0.0f, 10.0f, 0.2f);
  ASSERT_TRUE(fm::chunk_occluded(c, m.map));
  // The tile under the chunk's centre (the image centre, pixel (159.5, 89.5)).
  const std::size_t centre = static_cast<std::size_t>(89 / fm::kTileSize) * m.map.tiles_x + 159 / fm::kTileSize;
  m.depth[centre] = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(fm::chunk_occluded(c, m.map));
  m.depth[centre] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(fm::chunk_occluded(c, m.map));
  m.depth[centre] = 9.995f;  // saturated just in front of the chunk: within the depth slack
  EXPECT_FALSE(fm::chunk_occluded(chunk_at(0.0f, 0.0f, 10.0f, 0.0f), m.map));
}

TEST(OcclusionCull, TheEyesMoveWidensTheMargins) {
  // A wall with a hole of one tile: a chunk behind the wall next to the hole is culled while the
  // eye stays, and drawn once the eye has moved enough for the hole to uncover it.
  Map m = wall_at(2.0f);
  const std::size_t hole = static_cast<std::size_t>(89 / fm::kTileSize) * m.map.tiles_x + 159 / fm::kTileSize + 2;
  m.depth[hole] = std::numeric_limits<float>::infinity();
  const fm::ChunkBounds c = chunk_at(0.0f, 0.0f, 10.0f, 0.05f);
  EXPECT_TRUE(fm::chunk_occluded(c, m.map));
  m.map.shift = 0.3f;  // at 2 m and fx = 156 px: 23 px of parallax, past the hole 13 px away
  EXPECT_FALSE(fm::chunk_occluded(c, m.map));
  // The eye's move also brings the chunk nearer: at shift >= its lead over the wall it is drawn.
  Map near = wall_at(5.0f, 0.0f);
  const fm::ChunkBounds d = chunk_at(0.0f, 0.0f, 6.0f, 0.05f);
  EXPECT_TRUE(fm::chunk_occluded(d, near.map));
  near.map.shift = 1.2f;
  EXPECT_FALSE(fm::chunk_occluded(d, near.map));
}

double psnr_rgba8(const Image& a, const Image& b) {
  double se = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.rgba8.size(); ++i) {
    if (i % 4 == 3) continue;
    const double d = static_cast<double>(a.rgba8[i]) - static_cast<double>(b.rgba8[i]);
    se += d * d;
    ++n;
  }
  return se == 0.0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(255.0 * 255.0 * n / se);
}

RenderOptions exact_options(bool occlusion) {
  RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.lod_error_px = 2.0f;
  o.occlusion_culling = occlusion;
  return o;
}

// The same pose twice: the second frame culls the Gaussians the first found hidden, and draws the same
// picture (a culled Gaussian lies behind every pixel's opaque point: under 1/255 a pixel; the sort
// key's depth quantisation, over a shorter depth range, may reorder ties).
TEST(OcclusionCull, SamePoseAgainCullsAndDrawsTheSamePicture) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const test::SmallCity& city = test::small_flowers_city();
  cpu::CpuRenderer culled(city.lod, exact_options(true)), plain(city.lod, exact_options(false));
  std::size_t fewer = 0;
  for (const Camera& cam : city.views) {
    Image first, again, reference;
    culled.render(cam, first);
    culled.render(cam, again);
    EXPECT_TRUE(culled.last_stats().occlusion_map_used);
    const std::size_t listed = culled.last_stats().render_list_length;
    plain.render(cam, reference);
    EXPECT_FALSE(plain.last_stats().occlusion_map_used);
    EXPECT_LE(listed, plain.last_stats().render_list_length);
    fewer += listed < plain.last_stats().render_list_length ? 1 : 0;
    EXPECT_EQ(first.rgba8, reference.rgba8);  // the first frame has no map
    EXPECT_GE(psnr_rgba8(again, reference), 60.0);
  }
  EXPECT_GE(fewer, city.views.size() / 2) << "the fly-over's views see copies behind copies";
}

// A moving eye, and a fast turn: every frame against the unculled render of its pose.
TEST(OcclusionCull, MovingAndTurningFramesMatchTheUnculledRender) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const test::SmallCity& city = test::small_flowers_city();
  cpu::CpuRenderer culled(city.lod, exact_options(true)), plain(city.lod, exact_options(false));
  std::vector<Camera> path;
  for (const Camera& cam : city.views) {
    path.push_back(cam);
    // Then a 40-degree turn within one frame, and back.
    const glm::quat turn = glm::angleAxis(glm::radians(40.0f), glm::vec3(0.0f, 1.0f, 0.0f));
    path.push_back(Camera::from_pose(cam.position(), turn * cam.orientation(), cam.vertical_fov_deg(), cam.width,
                                     cam.height));
  }
  double worst = std::numeric_limits<double>::infinity();
  std::size_t culled_entries = 0, plain_entries = 0;
  for (const Camera& cam : path) {
    Image a, b;
    culled.render(cam, a);
    plain.render(cam, b);
    culled_entries += culled.last_stats().render_list_length;
    plain_entries += plain.last_stats().render_list_length;
    worst = std::min(worst, psnr_rgba8(a, b));
  }
  EXPECT_GE(worst, 40.0);
  EXPECT_LT(culled_entries, plain_entries);
}

}  // namespace
}  // namespace catgs
