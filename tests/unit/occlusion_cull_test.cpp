// Occlusion culling from the last frame (forward_model/occlusion.h, issue 72): the reprojection and
// the entry and chunk tests on hand-made maps, and the CPU core's frames with it against the same
// frames drawn without it on a real city (the oracle: the unculled render of the same pose).
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
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

// A per-pixel map drawn at test_view(): every pixel opaque at `depth`.
std::vector<float> wall_at(float depth) { return std::vector<float>(320 * 180, depth); }
std::size_t pixel(int x, int y) { return static_cast<std::size_t>(y) * 320 + x; }

// The map reprojected onto `now` (cpu::occlusion_reproject): its pixels, and the map of cells.
struct Reprojected {
  std::vector<float> pixels, cells;
  fm::OcclusionMap map;
};
Reprojected reproject(const std::vector<float>& last, const fm::View& now) {
  Reprojected r;
  r.map = cpu::occlusion_reproject(last.data(), test_view(), now, r.pixels, r.cells);
  return r;
}

TEST(OcclusionCull, SamePoseDrawsEachPixelAtItsOwnDepth) {
  std::vector<float> last = wall_at(5.0f);
  for (int y = 0; y < 180; ++y)
    for (int x = 0; x < 320; ++x) last[pixel(x, y)] = 4.0f + 0.001f * static_cast<float>(x);  // a slanted wall
  const Reprojected r = reproject(last, test_view());
  ASSERT_EQ(r.pixels.size(), last.size());
  // A pixel centre is a corner of up to four quads, each at its deepest corner; the nearest wins:
  // the pixel's own depth (the wall deepens to the right), or its right-hand neighbour's where the
  // corner's rounding falls a hair left of the centre (only the quads to its right then cover it;
  // always in the first column). Every pixel is covered.
  for (int y = 0; y < 180; ++y)
    for (int x = 0; x < 320; ++x) {
      const float d = r.pixels[pixel(x, y)];
      EXPECT_GE(d, last[pixel(x, y)] - 1e-5f) << x;
      EXPECT_LE(d, last[pixel(std::min(x + 1, 319), y)] + 1e-5f) << x;
    }
  // The cells: the deepest of their pixels (4 x 4, 8 x 8, 16 x 16).
  EXPECT_EQ(r.map.cells_x[0], 80);
  EXPECT_EQ(r.map.cells_y[2], 12);  // 180 / 16, rounded up
  auto deepest = [&](int x0, int x1, int y0, int y1) {
    float d = 0.0f;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) d = std::max(d, r.pixels[pixel(x, y)]);
    return d;
  };
  EXPECT_EQ(r.map.cells[0][0], deepest(0, 3, 0, 3));
  EXPECT_EQ(r.map.cells[1][40 + 2], deepest(16, 23, 8, 15));  // cell (2, 1) of 8 x 8
  EXPECT_EQ(r.map.cells[2][3], deepest(48, 63, 0, 15));
  EXPECT_GT(r.map.cells[2][3], r.map.cells[2][2]);
}

TEST(OcclusionCull, ATurnLeavesWhatTheLastFrameDidNotSeeWithoutData) {
  std::vector<float> last = wall_at(5.0f);
  const Reprojected r = reproject(last, test_view(glm::vec3(0.0f), 10.0f));
  // A turn to the side: one edge of the new image looks past the last image's edge (no data), the
  // other still at the wall.
  int unknown = 0, known = 0;
  for (int x = 0; x < 320; ++x) (std::isinf(r.pixels[pixel(x, 90)]) ? unknown : known) += 1;
  EXPECT_GE(unknown, 20);
  EXPECT_GE(known, 200);
  EXPECT_TRUE(std::isinf(r.pixels[pixel(0, 90)]) != std::isinf(r.pixels[pixel(319, 90)]));
  // A pixel that never became opaque (+inf) or NaN breaks the quads it is a corner of.
  last[pixel(100, 50)] = std::numeric_limits<float>::infinity();
  last[pixel(200, 50)] = std::numeric_limits<float>::quiet_NaN();
  const Reprojected same = reproject(last, test_view());
  EXPECT_TRUE(std::isinf(same.pixels[pixel(100, 50)]));
  EXPECT_TRUE(std::isinf(same.pixels[pixel(200, 50)]));
  EXPECT_FALSE(std::isinf(same.pixels[pixel(150, 50)]));
}

TEST(OcclusionCull, TheEyesMoveOpensTheGapBetweenTwoDepthsAtTheFartherOne) {
  // A near wall (depth 2) over the left half, a far one (10) over the right; the eye moves right by
  // 0.25, so (focal 156 px) the near wall slides left by 19.5 px and the far one by 3.9: a gap of
  // about 16 px opens between them, which the last frame did not see. The quads across the edge
  // span it at the farther depth: what lies behind the far wall there stays hidden, what lies
  // between the walls is drawn. The far wall's 4 px at the right edge have no data.
  std::vector<float> last = wall_at(10.0f);
  for (int y = 0; y < 180; ++y)
    for (int x = 0; x < 160; ++x) last[pixel(x, y)] = 2.0f;
  const Reprojected r = reproject(last, test_view(glm::vec3(0.25f, 0.0f, 0.0f)));
  for (int x = 0; x < 139; ++x) EXPECT_NEAR(r.pixels[pixel(x, 90)], 2.0f, 1e-4f) << x;
  for (int x = 142; x < 315; ++x) EXPECT_NEAR(r.pixels[pixel(x, 90)], 10.0f, 1e-3f) << x;
  for (int x = 317; x < 320; ++x) EXPECT_TRUE(std::isinf(r.pixels[pixel(x, 90)])) << x;
}

TEST(OcclusionCull, AnEntryBehindItsPixelsIsHiddenOneInFrontOrOverAnOpenPixelIsNot) {
  std::vector<float> last = wall_at(5.0f);
  last[pixel(150, 90)] = std::numeric_limits<float>::infinity();  // a pixel saw the background
  const Reprojected r = reproject(last, test_view());
  const glm::vec3 small(0.5f, 0.0f, 0.5f);  // conic of a Gaussian of about 1.4 px sigma
  const float q_max = 4.0f;                 // its box: +-2.9 px
  // Tile (3, 3): pixels 48..63.
  EXPECT_TRUE(fm::entry_hidden(r.map, glm::vec2(55.0f, 55.0f), small, q_max, 10.0f, 3, 3, 320, 180));
  EXPECT_FALSE(fm::entry_hidden(r.map, glm::vec2(55.0f, 55.0f), small, q_max, 4.0f, 3, 3, 320, 180));    // in front
  EXPECT_FALSE(fm::entry_hidden(r.map, glm::vec2(55.0f, 55.0f), small, q_max, 5.002f, 3, 3, 320, 180));  // slack
  // Beside the open pixel (150, 90): its quads have no data, so a box over them is kept.
  EXPECT_FALSE(fm::entry_hidden(r.map, glm::vec2(151.0f, 91.0f), small, q_max, 10.0f, 9, 5, 320, 180));
  EXPECT_TRUE(fm::entry_hidden(r.map, glm::vec2(140.0f, 84.0f), small, q_max, 10.0f, 8, 5, 320, 180));
  // A degenerate conic tests nothing.
  EXPECT_FALSE(fm::entry_hidden(r.map, glm::vec2(55.0f, 55.0f), glm::vec3(0.0f), q_max, 10.0f, 3, 3, 320, 180));
}

// A chunk's bound over hand-placed means (every Gaussian of scale `scale` and opacity logit 2).
fm::ChunkBounds chunk_of(glm::vec3 lo, glm::vec3 hi, float scale = 0.01f) {
  const std::vector<float> means = {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z};
  const std::vector<float> log_scales(6, std::log(scale)), opacity_logits(2, 2.0f);
  return fm::chunk_bounds(means.data(), log_scales.data(), opacity_logits.data(), 2)[0];
}

TEST(OcclusionCull, AChunkBehindTheMapIsHiddenWholeOneInFrontAcrossOrOverAnOpenPixelIsNot) {
  std::vector<float> last = wall_at(5.0f);
  const Reprojected r = reproject(last, test_view());
  const fm::View v = test_view();
  // A small chunk at depth 10 straight ahead: its box (means +-3 px, ellipses +-4 px) lies behind.
  EXPECT_TRUE(fm::chunk_hidden(r.map, chunk_of({-0.2f, -0.2f, 9.8f}, {0.2f, 0.2f, 10.2f}), v));
  EXPECT_FALSE(fm::chunk_hidden(r.map, chunk_of({-0.2f, -0.2f, 4.0f}, {0.2f, 0.2f, 4.5f}), v));   // in front
  EXPECT_FALSE(fm::chunk_hidden(r.map, chunk_of({-0.2f, -0.2f, 4.99f}, {0.2f, 0.2f, 10.f}), v));  // its near corner
  EXPECT_FALSE(fm::chunk_hidden(r.map, chunk_of({-0.2f, -0.2f, 5.002f}, {0.2f, 0.2f, 6.f}), v));  // within the slack
  // A chunk as wide as the image reads no more than kOcclusionChunkCells cells a side: kept.
  EXPECT_FALSE(fm::chunk_hidden(r.map, chunk_of({-8.0f, -0.2f, 9.8f}, {8.0f, 0.2f, 10.2f}), v));
  // Straddling the near plane, or without a map: kept.
  EXPECT_FALSE(fm::chunk_hidden(r.map, chunk_of({-0.2f, -0.2f, -1.0f}, {0.2f, 0.2f, 10.2f}), v));
  EXPECT_FALSE(fm::chunk_hidden(fm::OcclusionMap{}, chunk_of({-0.2f, -0.2f, 9.8f}, {0.2f, 0.2f, 10.2f}), v));
  // One pixel that saw the background under the chunk's box (the image centre is (159.5, 89.5)).
  last[pixel(162, 92)] = std::numeric_limits<float>::infinity();
  const Reprojected open = reproject(last, test_view());
  EXPECT_FALSE(fm::chunk_hidden(open.map, chunk_of({-0.2f, -0.2f, 9.8f}, {0.2f, 0.2f, 10.2f}), v));
  // Its largest Gaussian widens the box: 60 px left of the open pixel (means at u 94-103), a chunk
  // of scale 0.01 (bound +-5 px) is hidden, and so is one of scale 0.5 (its ellipse bound, about
  // 32 px at q_max 10.8 with the Jacobian's row at the box's own x / z, ends short of the cell of
  // 16 px over the pixel; the norm of both rows at the clamp, 58 px, reached it); one of scale 1.2
  // (about 72 px) is not.
  EXPECT_TRUE(fm::chunk_hidden(open.map, chunk_of({-4.1f, -0.2f, 9.8f}, {-3.7f, 0.2f, 10.2f}), v));
  EXPECT_TRUE(fm::chunk_hidden(open.map, chunk_of({-4.1f, -0.2f, 9.8f}, {-3.7f, 0.2f, 10.2f}, 0.5f), v));
  EXPECT_FALSE(fm::chunk_hidden(open.map, chunk_of({-4.1f, -0.2f, 9.8f}, {-3.7f, 0.2f, 10.2f}, 1.2f), v));
}

// The entries of one Gaussian in view v (tiles its ellipse reaches) and how many of them
// entry_hidden drops against map m: the oracle the whole-chunk test must not
// outrun.
struct EntriesHidden {
  int entries = 0, hidden = 0;
};
EntriesHidden entries_hidden(const fm::OcclusionMap& m, const fm::View& v, const float* mean3, const float* log_scale,
                             const float* rotation, float logit) {
  EntriesHidden e;
  const glm::vec3 p_cam = v.R * glm::vec3(mean3[0], mean3[1], mean3[2]) + v.t;
  const float q_max = fm::opacity_aware_qmax(fm::sigmoid(logit));
  if (!(q_max > 0.0f) || !(p_cam.z > v.near_plane)) return e;
  const glm::vec2 mean2d(v.fx * p_cam.x / p_cam.z + v.cx - 0.5f, v.fy * p_cam.y / p_cam.z + v.cy - 0.5f);
  const fm::Cov3 cov3 = fm::covariance_3d({log_scale[0], log_scale[1], log_scale[2]},
                                          {rotation[0], rotation[1], rotation[2], rotation[3]});
  const glm::vec3 cov2 = fm::covariance_2d(cov3, v.R, p_cam, v.fx, v.fy, v.tan_half_fov);
  glm::vec3 conic;
  if (!fm::conic_from_cov2d(cov2, &conic)) return e;
  const fm::TileRect rect = fm::ellipse_tile_rect(mean2d, cov2, q_max, v.width, v.height);
  for (int ty = rect.y0; ty < rect.y1; ++ty)
    for (int tx = rect.x0; tx < rect.x1; ++tx) {
      if (!fm::ellipse_touches_tile(mean2d, conic, q_max, tx, ty, v.width, v.height)) continue;
      ++e.entries;
      e.hidden += fm::entry_hidden(m, mean2d, conic, q_max, p_cam.z, tx, ty, v.width, v.height) ? 1 : 0;
    }
  return e;
}

// A rough map (a wall between depth 4.5 and 7.5), drawn from the last pose and read from v.
Reprojected rough_wall_map(const fm::View& v) {
  std::vector<float> last(320 * 180);
  for (int y = 0; y < 180; ++y)
    for (int x = 0; x < 320; ++x)
      last[pixel(x, y)] =
          6.0f + 1.5f * std::sin(0.11f * static_cast<float>(x)) * std::cos(0.07f * static_cast<float>(y));
  return reproject(last, v);
}

// Chunks of 64 random Gaussians (within up to `spread` of a centre in view between depths z0 and
// z0 + z_span, scales up to about scale_max) tested by chunk_hidden against map m, each Gaussian of a hidden one checked
// against the per-entry test (every entry hidden, or the chunk test outran its oracle).
struct ChunkOracle {
  int hidden = 0, kept = 0, entries = 0;
};
ChunkOracle check_hidden_chunks(const fm::OcclusionMap& m, const fm::View& v, float z0, float z_span, float spread,
                                float scale_max, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  ChunkOracle o;
  for (int c = 0; c < 4000; ++c) {
    const glm::vec3 centre((u(rng) - 0.5f) * 10.0f, (u(rng) - 0.5f) * 6.0f, z0 + z_span * u(rng));
    const float size = 0.05f + spread * u(rng);
    constexpr int kCount = 64;
    std::vector<float> means, log_scales, logits, rotations;
    for (int i = 0; i < kCount; ++i) {
      for (int k = 0; k < 3; ++k) means.push_back(centre[k] + size * (u(rng) - 0.5f));
      for (int k = 0; k < 3; ++k) log_scales.push_back(std::log(0.002f + scale_max * u(rng) * u(rng)));
      logits.push_back(-3.0f + 8.0f * u(rng));
      for (int k = 0; k < 4; ++k) rotations.push_back(u(rng) - 0.5f);
    }
    const fm::ChunkBounds b = fm::chunk_bounds(means.data(), log_scales.data(), logits.data(), kCount)[0];
    if (!fm::chunk_hidden(m, b, v)) {
      ++o.kept;
      continue;
    }
    ++o.hidden;
    for (int i = 0; i < kCount; ++i) {
      const EntriesHidden e = entries_hidden(m, v, &means[3 * i], &log_scales[3 * i], &rotations[4 * i], logits[i]);
      o.entries += e.entries;
      EXPECT_EQ(e.hidden, e.entries) << "chunk " << c << " Gaussian " << i;
    }
  }
  return o;
}

// Near blocks (depth 5) of 56 px with far gaps (depth 12) of 8 px between them, drawn from the
// last pose and read from v: whether what lies between the two depths is hidden turns on how far
// its box reaches.
Reprojected block_wall_map(const fm::View& v) {
  std::vector<float> last(320 * 180);
  for (int y = 0; y < 180; ++y)
    for (int x = 0; x < 320; ++x) last[pixel(x, y)] = x % 64 < 56 && y % 64 < 56 ? 5.0f : 12.0f;
  return reproject(last, v);
}

// The chunk test against the per-entry one: over a rough, moved map (small Gaussians, behind or
// across the wall) and over the blocks and gaps (larger ones, between the two depths), every
// entry of every Gaussian of a chunk that chunk_hidden drops is one that entry_hidden drops.
TEST(OcclusionCull, AHiddenChunksEveryEntryIsHiddenByTheEntryTest) {
  const fm::View v = test_view(glm::vec3(0.05f, 0.02f, 0.0f), 2.0f);
  const ChunkOracle rough = check_hidden_chunks(rough_wall_map(v).map, v, 4.0f, 10.0f, 0.6f, 0.08f, 72);
  EXPECT_GE(rough.hidden, 200) << "chunks behind the rough wall";
  EXPECT_GE(rough.kept, 200) << "chunks in front of it, across it or off the image";
  EXPECT_GE(rough.entries, 2000);
  const Reprojected blocks = block_wall_map(v);
  const ChunkOracle gaps = check_hidden_chunks(blocks.map, v, 6.0f, 5.0f, 0.2f, 0.2f, 74);
  EXPECT_GE(gaps.hidden, 50) << "chunks behind the near blocks";
  EXPECT_GE(gaps.kept, 200) << "over the gaps, across them or off the image";
  EXPECT_GE(gaps.entries, 5000);
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
// key's depth quantisation, over a shorter depth range, may reorder ties). The first frame of each
// view reads the last view's map, from another pose of the fly-over: the very first has none.
TEST(OcclusionCull, SamePoseAgainCullsAndDrawsTheSamePicture) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const test::SmallCity& city = test::small_flowers_city();
  cpu::CpuRenderer culled(city.lod, exact_options(true)), plain(city.lod, exact_options(false));
  std::size_t fewer = 0;
  for (std::size_t v = 0; v < city.views.size(); ++v) {
    const Camera& cam = city.views[v];
    Image first, again, reference;
    culled.render(cam, first);
    EXPECT_EQ(culled.last_stats().occlusion_map_used, v > 0);
    culled.render(cam, again);
    EXPECT_TRUE(culled.last_stats().occlusion_map_used);
    const std::size_t listed = culled.last_stats().render_list_length;
    plain.render(cam, reference);
    EXPECT_FALSE(plain.last_stats().occlusion_map_used);
    EXPECT_LE(listed, plain.last_stats().render_list_length);
    fewer += listed < plain.last_stats().render_list_length ? 1 : 0;
    if (v == 0) EXPECT_EQ(first.rgba8, reference.rgba8);  // no map
    EXPECT_GE(psnr_rgba8(again, reference), 60.0);
  }
  EXPECT_GE(fewer, city.views.size() / 2) << "the fly-over's views see copies behind copies";
}

// The CPU's bound on what a map could drop before pre-processing (cpu::count_hidden, the frame's
// own per-pixel map): runs of 32 carry tighter bounds than their chunk (a nearer-or-equal box, a
// farther-or-equal nearest mean), so they hide at least what the chunks hide, and no more than the
// cut's Gaussians in view; entries hidden and changing pixels are parts of the list.
TEST(OcclusionCull, TheOwnMapsBoundsNestFromChunksToRunsToTheCut) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const test::SmallCity& city = test::small_flowers_city();
  cpu::CpuRenderer counted(city.lod, exact_options(false));
  counted.count_changes(true);
  std::size_t groups = 0, chunks = 0;
  for (std::size_t v = 0; v < city.views.size(); v += 2) {
    Image out;
    counted.render(city.views[v], out);
    const FrameStats& s = counted.last_stats();
    EXPECT_LE(s.gaussians_in_hidden_chunks, s.gaussians_in_hidden_groups) << v;
    EXPECT_LE(s.gaussians_in_hidden_groups, s.gaussians_preprocessed) << v;
    EXPECT_LE(s.gaussians_hidden_alone, s.visible) << v;
    EXPECT_LE(s.entries_hidden_pixels, s.render_list_length) << v;
    EXPECT_LE(s.entries_changing_pixels, s.render_list_length) << v;
    EXPECT_GT(s.entries_changing_pixels, 0u) << v;
    groups += s.gaussians_in_hidden_groups;
    chunks += s.gaussians_in_hidden_chunks;
  }
  EXPECT_GT(groups, chunks) << "some runs of 32 lie behind nearer copies where their chunk does not";
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
