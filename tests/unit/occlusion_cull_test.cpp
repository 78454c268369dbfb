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
#include "renderer/renderer.h"
#include "small_city.h"
#include "test_data.h"

namespace catgs {
namespace {

// A 320 x 180 camera at `eye` looking down +z, turned by `yaw_deg` about +y.
fm::View test_view(glm::vec3 eye = glm::vec3(0.0f), float yaw_deg = 0.0f) {
  const glm::quat q = glm::angleAxis(glm::radians(yaw_deg), glm::vec3(0.0f, 1.0f, 0.0f));
  return fm::view_of(Camera::from_pose(eye, q, 60.0f, 320, 180));
}

// A map drawn at test_view(): every tile opaque at `depth`; `now` reads it.
struct Map {
  std::vector<float> depth, now_depth;
  fm::OcclusionMap map;
};
Map wall_at(float depth, const fm::View& now = test_view()) {
  Map m;
  m.map = fm::occlusion_map(nullptr, test_view(), now);
  m.depth.assign(static_cast<std::size_t>(m.map.tiles_x) * m.map.tiles_y, depth);
  m.map.depth = m.depth.data();
  return m;
}
// The map reprojected onto `now`'s tiles (as cpu::occlusion_reproject).
void reproject(Map& m, const fm::View& now) {
  cpu::occlusion_reproject(m.map, now, cpu::TileGrid::of(now.width, now.height), m.now_depth);
  m.map.now_depth = m.now_depth.data();
  m.map.now_tiles_x = cpu::TileGrid::of(now.width, now.height).tiles_x;
}
std::size_t tile_index(int tx, int ty) { return static_cast<std::size_t>(ty) * 20 + tx; }  // 320 / 16 tiles a row

TEST(OcclusionCull, SamePoseReadsEachTilesOwnDepth) {
  Map m = wall_at(5.0f);
  for (std::size_t t = 0; t < m.depth.size(); ++t) m.depth[t] = 1.0f + static_cast<float>(t);
  reproject(m, test_view());
  ASSERT_EQ(m.now_depth.size(), m.depth.size());
  for (std::size_t t = 0; t < m.depth.size(); ++t) EXPECT_EQ(m.now_depth[t], m.depth[t]) << t;
}

TEST(OcclusionCull, ATurnReadsTheTilesItTurnedTo) {
  Map m = wall_at(5.0f);
  for (std::size_t t = 0; t < m.depth.size(); ++t) m.depth[t] = 1.0f + static_cast<float>(t % 20);  // by column
  const fm::View turned = test_view(glm::vec3(0.0f), 10.0f);
  reproject(m, turned);
  // A turn to the side: the tiles now at the image's centre saw, last frame, columns to one side;
  // the ones now at that edge saw past the last image's edge (no data).
  const float centre = m.now_depth[tile_index(10, 5)];
  EXPECT_TRUE(std::isfinite(centre));
  EXPECT_NE(centre, m.depth[tile_index(10, 5)]);
  int unknown = 0;
  for (int tx = 0; tx < 20; ++tx) unknown += std::isinf(m.now_depth[tile_index(tx, 5)]) ? 1 : 0;
  EXPECT_GE(unknown, 2);
  EXPECT_LE(unknown, 8);
}

TEST(OcclusionCull, TheEyesMoveWidensTheBoxByTheParallax) {
  // A wall at 2 with one tile that never became opaque: the same pose reads it only there; once
  // the eye has moved, the tiles beside it read it too (the nearer the wall, the wider).
  Map m = wall_at(2.0f);
  m.depth[tile_index(10, 5)] = std::numeric_limits<float>::infinity();
  reproject(m, test_view());
  EXPECT_TRUE(std::isinf(m.now_depth[tile_index(10, 5)]));
  EXPECT_EQ(m.now_depth[tile_index(12, 5)], 2.0f);
  const fm::View moved = test_view(glm::vec3(0.25f, 0.0f, 0.0f));
  Map n = wall_at(2.0f, moved);
  n.depth = m.depth;
  n.map.depth = n.depth.data();
  ASSERT_NEAR(n.map.shift, 0.25f, 1e-6f);
  reproject(n, moved);
  EXPECT_TRUE(std::isinf(n.now_depth[tile_index(11, 5)]));  // 0.25 * 156 / 2 = 19 px of parallax
  EXPECT_TRUE(std::isinf(n.now_depth[tile_index(9, 5)]));
  EXPECT_EQ(n.now_depth[tile_index(14, 5)], 2.0f);
  // NaN in the map: no data.
  Map k = wall_at(2.0f);
  k.depth[tile_index(3, 3)] = std::numeric_limits<float>::quiet_NaN();
  reproject(k, test_view());
  EXPECT_TRUE(std::isinf(k.now_depth[tile_index(3, 3)]));
}

TEST(OcclusionCull, AnEntryBehindTheTilesDepthIsHiddenOneInFrontOrUnderAnOpenTileIsNot) {
  Map m = wall_at(5.0f);
  m.depth[tile_index(9, 5)] = std::numeric_limits<float>::infinity();  // a pixel saw the background
  reproject(m, test_view());
  EXPECT_TRUE(fm::entry_hidden(m.now_depth[tile_index(3, 3)], 10.0f));
  EXPECT_FALSE(fm::entry_hidden(m.now_depth[tile_index(3, 3)], 4.0f));    // in front of the wall
  EXPECT_FALSE(fm::entry_hidden(m.now_depth[tile_index(3, 3)], 5.002f));  // within the depth slack
  EXPECT_FALSE(fm::entry_hidden(m.now_depth[tile_index(9, 5)], 10.0f));
  EXPECT_FALSE(fm::entry_hidden(m.now_depth[tile_index(3, 3)], -INFINITY));  // no map: -inf
  EXPECT_FALSE(fm::entry_hidden(std::numeric_limits<float>::quiet_NaN(), 10.0f));
  // The old depth of a mean: in the map's view, less the eye's move.
  Map n = wall_at(5.0f, test_view(glm::vec3(0.0f, 0.0f, 1.0f)));
  reproject(n, test_view(glm::vec3(0.0f, 0.0f, 1.0f)));
  EXPECT_NEAR(fm::occlusion_old_depth(glm::vec3(0.3f, 0.2f, 7.0f), n.map), 6.0f, 1e-5f);
  fm::OcclusionMap none;
  EXPECT_EQ(fm::occlusion_old_depth(glm::vec3(0.3f, 0.2f, 7.0f), none), -INFINITY);
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

// The same pose twice: the second frame drops the entries the first found hidden, and draws the same
// picture (a dropped entry lies behind every pixel's opaque point: under 1/255 a pixel; the sort
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
    path.push_back(
        Camera::from_pose(cam.position(), turn * cam.orientation(), cam.vertical_fov_deg(), cam.width, cam.height));
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
