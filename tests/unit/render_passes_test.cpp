// Issue 35: a frame over the render-list budget is drawn in passes of tiles (exact, vanilla, and
// catgs's frames without a window), or, for a catgs key frame, with a narrower window, instead of
// being refused; giant Gaussians (issue 22) are still refused. The budgets here are set low on
// purpose so that an ordinary scene needs the passes.
//
// Equality: a pass keeps the whole frame's camera, sort key and split length, so each tile blends
// the same entries in the same order as in one pass: the CPU images are compared bit for bit
// (float RGB and 8-bit). catgs frames drawn with a narrower window are not the same computation
// as the unbudgeted run's (other groups, other sub-frames), so those are compared by PSNR.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <memory>
#include <random>
#include <string>

#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

#include "camera/trace.h"
#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "renderer/render_passes.h"
#include "renderer/renderer.h"
#include "test_data.h"

namespace catgs {
namespace {

bool same_bits(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.rgb.size() == b.rgb.size() &&
         std::memcmp(a.rgb.data(), b.rgb.data(), a.rgb.size() * sizeof(float)) == 0 && a.rgba8 == b.rgba8;
}

// The biker seen from the front at 640x360 (its list: about 0.5 M entries exact).
Camera biker_view(const GaussianModel& m) {
  const Bounds b = m.bounds();
  GeneratorParams p;
  p.width = 640;
  p.height = 360;
  p.duration_s = 1.0;
  return make_orbit(b, 0.9f * glm::length(b.extent()), 0.2f * glm::length(b.extent()), 90.0f, p)[30].camera;
}

// A budget of `limit` entries a pass at any frame size (min_entries alone sets it).
RenderListBudget budget_of(std::uint64_t limit) {
  RenderListBudget b;
  b.max_entries_per_tile = 0;
  b.min_entries = limit;
  b.max_passes = 1000;
  return b;
}

// The heaviest tile's entries in the last frame of a one-pass renderer.
std::uint64_t heaviest_tile(const cpu::CpuRenderer& r) {
  std::uint64_t most = 0;
  for (const glm::uvec2 range : r.tile_ranges()) most = std::max<std::uint64_t>(most, range.y - range.x);
  return most;
}

TEST(RenderPasses, ExactAndVanillaInPassesEqualOnePass) {
  const auto model = test::cached_scene(test::bundled_scene());
  const Camera cam = biker_view(*model);
  for (const Pipeline p : {Pipeline::exact, Pipeline::vanilla}) {
    SCOPED_TRACE(pipeline_name(p));
    RenderOptions o;
    o.pipeline = p;
    o.speculation.min_slice_entries = 0;  // the paper's split length l = L / t: tiles really split
    cpu::CpuRenderer one(model, o);
    Image want;
    one.render(cam, want);
    const std::uint64_t entries = one.last_stats().render_list_length, heaviest = heaviest_tile(one);
    ASSERT_EQ(one.last_stats().passes, 1);
    // Bands of rows (a third of the list a pass), then runs of single rows' tiles (twice the
    // heaviest tile a pass: the crowded rows are over it).
    for (const std::uint64_t limit : {entries / 3, 2 * heaviest}) {
      SCOPED_TRACE("limit " + std::to_string(limit));
      o.list_budget = budget_of(limit);
      cpu::CpuRenderer passes(model, o);
      Image got;
      passes.render(cam, got);
      const FrameStats& s = passes.last_stats();
      std::cout << "[ info ] " << pipeline_name(p) << " " << entries << " entries, limit " << limit << ": " << s.passes
                << " passes, longest " << s.longest_pass << "\n";
      EXPECT_GE(s.passes, static_cast<int>((entries + limit - 1) / limit));
      EXPECT_LE(s.longest_pass, limit);
      EXPECT_EQ(s.render_list_length, entries);
      EXPECT_EQ(s.visible, one.last_stats().visible);
      EXPECT_TRUE(same_bits(got, want)) << "PSNR " << psnr_rgba8(got, want);
    }
    // A tile alone over the budget: no pass can hold it.
    o.list_budget = budget_of(heaviest - 1);
    cpu::CpuRenderer refused(model, o);
    Image out;
    try {
      refused.render(cam, out);
      ADD_FAILURE() << "drawn in " << refused.last_stats().passes << " passes";
    } catch (const RenderBudgetError& e) {
      EXPECT_NE(std::string(e.what()).find("alone lists " + std::to_string(heaviest) + " entries"), std::string::npos)
          << e.what();
    }
    // More passes than max_passes: refused before any is drawn.
    o.list_budget = budget_of(entries / 3);
    o.list_budget.max_passes = 2;
    cpu::CpuRenderer too_many(model, o);
    EXPECT_THROW(too_many.render(cam, out), RenderBudgetError);
  }
}

// A pass is not a smaller camera: a Gaussian near the image edge is projected with the whole
// frame's field of view clamp and tested against its own tiles only.
TEST(RenderPasses, RegionClipsTilesNotTheCamera) {
  const fm::TileRect r{2, 3, 9, 7};
  const fm::TileRect c = fm::clip_tile_rect(r, {0, 5, 40, 6});
  EXPECT_EQ(c.x0, 2);
  EXPECT_EQ(c.x1, 9);
  EXPECT_EQ(c.y0, 5);
  EXPECT_EQ(c.y1, 6);
  EXPECT_EQ(fm::tile_count(fm::clip_tile_rect(r, {0, 10, 40, 12})), 0);
  EXPECT_EQ(fm::tile_count(fm::clip_tile_rect(r, fm::kAllTiles)), fm::tile_count(r));
  // Regions are whole rows or a part of one row: one run of tile ids.
  EXPECT_EQ(first_tile({0, 2, 40, 5}, 40), 80u);
  EXPECT_EQ(end_tile({0, 2, 40, 5}, 40), 200u);
  EXPECT_EQ(first_tile({7, 4, 19, 5}, 40), 167u);
  EXPECT_EQ(end_tile({7, 4, 19, 5}, 40), 179u);
}

// The driver alone, on made-up counts: bands first, crowded bands cut again, every tile drawn once.
TEST(RenderPasses, DriverCoversEveryTileOnceWithinTheLimit) {
  const int w = 320, h = 160;  // 20 x 10 tiles
  std::vector<std::uint64_t> load(200, 10);
  for (int x = 0; x < 20; ++x) load[static_cast<std::size_t>(4 * 20 + x)] = 300;  // a crowded row
  std::uint64_t total = 0;
  for (auto v : load) total += v;
  const RenderListBudget b = budget_of(1000);
  auto sum = [&](const fm::TileRect& r) {
    std::uint64_t n = 0;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) n += load[static_cast<std::size_t>(y * 20 + x)];
    return n;
  };
  std::vector<int> drawn(200, 0);
  const PassesDrawn d = draw_in_passes(b, w, h, 28, total, 1000000, sum, [&](const fm::TileRect& r, std::uint64_t n) {
    EXPECT_LE(n, 1000u);
    EXPECT_EQ(n, sum(r));
    EXPECT_TRUE(r.y1 - r.y0 == 1 || (r.x0 == 0 && r.x1 == 20)) << "not one run of tile ids";
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) ++drawn[static_cast<std::size_t>(y * 20 + x)];
  });
  EXPECT_EQ(std::count(drawn.begin(), drawn.end(), 1), 200);
  EXPECT_GE(d.passes, static_cast<int>((total + 999) / 1000));
  EXPECT_LE(d.longest, 1000u);
  EXPECT_GT(d.counted, d.passes);  // the crowded row's band was cut again
}

// The giant-Gaussian rule: refused by their average reach, not by the list's length alone.
TEST(RenderPasses, GiantGaussiansAreRefusedManySmallOnesAreNot) {
  const RenderListBudget b;  // the defaults
  const std::uint64_t limit = b.max_entries(1280, 720, 28);
  // 20 k Gaussians each in all 3600 tiles (issue 22's scene): refused.
  EXPECT_THROW(b.check_passes(20000ull * 3600, 20000, 1280, 720, 28), RenderBudgetError);
  // 7 M Gaussians listing 59.35 M entries (issue 35's city view): passes.
  EXPECT_NO_THROW(b.check_passes(59350784, 7000000, 1280, 720, 28));
  // Within the budget nothing is checked.
  EXPECT_NO_THROW(b.check_passes(limit, 1, 1280, 720, 28));
  // More than max_passes passes' worth: refused.
  EXPECT_THROW(b.check_passes(limit * b.max_passes + 1, 1ull << 32, 1280, 720, 28), RenderBudgetError);
  EXPECT_NO_THROW(b.check_passes(limit * b.max_passes, 1ull << 32, 1280, 720, 28));
  // unlimited(): no passes (only the 2^32 - 1 limit, refused as before).
  EXPECT_THROW(RenderListBudget::unlimited().check_passes(1ull << 32, 1ull << 30, 3840, 2160, 28), RenderBudgetError);
}

// catgs refuses them too, with or without a window (a trail list of giant Gaussians is refused
// by its reach before any narrowing). 2000 of them at 320x180 with a budget of 100 k entries:
// 480 k entries, every Gaussian in all 240 tiles.
TEST(RenderPasses, GiantGaussiansStillRefusedByCatgs) {
  RenderOptions o;
  o.pipeline = Pipeline::catgs;
  o.list_budget = budget_of(100000);
  cpu::SpeculativeRenderer r(test::giant_gaussians(2000, 5.0f), o);
  const Camera cam =
      Camera::from_pose(glm::vec3(0.0f, 0.0f, -5.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, 320, 180);
  Image out;
  for (int k = 0; k < 3; ++k) {  // the first frame has no motion history (W = 0), the later ones a window
    try {
      r.render_at(cam, k / 120.0, out);
      ADD_FAILURE() << "frame " << k << " drawn";
    } catch (const RenderBudgetError& e) {
      EXPECT_NE(std::string(e.what()).find("render list of 480000 entries"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("cover much of the screen"), std::string::npos) << e.what();
    }
  }
}

// catgs over an orbit of the biker: key frames whose trail list is over the budget narrow their
// window; with a budget below even the exact list every frame falls back to an exact frame drawn
// in passes, equal bit for bit to the exact pipeline's frame of the same pose. A narrowed run is
// not the unbudgeted run (its groups differ, so other frames are sub-frames), so its frames are
// held to catgs's own quality against the exact render of each pose: key frames >= 60 dB (full
// renders; only their split lengths differ), sub-frames the speculation tests' mean >= 45 dB and
// min >= 35 dB.
TEST(RenderPasses, CatgsKeyFramesNarrowOrFallBack) {
  const auto model = test::cached_scene(test::bundled_scene());
  const Bounds bb = model->bounds();
  GeneratorParams g;
  g.width = 320;
  g.height = 180;
  g.duration_s = 0.15;  // 19 frames at 120 Hz, 120 degrees a second: trails grow with W
  const Trace trace = make_orbit(bb, 0.9f * glm::length(bb.extent()), 0.2f * glm::length(bb.extent()), 18.0f, g);
  RenderOptions o;
  o.pipeline = Pipeline::catgs;
  o.speculation.min_slice_entries = 0;
  const RenderOptions catgs_o = o;
  RenderOptions exact_o = o;
  exact_o.pipeline = Pipeline::exact;
  cpu::CpuRenderer exact(model, exact_o);
  Image e;
  exact.render(trace[0].camera, e);
  const std::uint64_t exact_entries = exact.last_stats().render_list_length;

  // 1. Halfway between the shortest and the longest W = 4 trail list of the unbudgeted run: the
  // longer W = 4 lists are narrowed (on this orbit the W = 2 and W = 1 lists are 1-5% shorter).
  cpu::SpeculativeRenderer first_run(model, o);
  std::uint64_t shortest_w4 = UINT64_MAX, longest_w4 = 0;
  for (const auto& tc : trace) {
    first_run.render_at(tc.camera, tc.time_s, e);
    const FrameStats& s = first_run.last_stats();
    if (s.key_frame && s.window == 4) {
      shortest_w4 = std::min<std::uint64_t>(shortest_w4, s.render_list_length);
      longest_w4 = std::max<std::uint64_t>(longest_w4, s.render_list_length);
    }
  }
  ASSERT_LT(shortest_w4, longest_w4) << "fewer than two key frames with W = 4";
  ASSERT_GT(shortest_w4, exact_entries);
  const std::uint64_t limit = (shortest_w4 + longest_w4) / 2;
  cpu::SpeculativeRenderer free_run(model, catgs_o);
  o.list_budget = budget_of(limit);
  cpu::SpeculativeRenderer narrowed(model, o);
  // 2. A third of the exact list: every key frame falls back to an exact frame, in passes.
  o.list_budget = budget_of(exact_entries / 3);
  cpu::SpeculativeRenderer fallback(model, o);
  int narrowed_keys = 0, narrowed_to_zero = 0, narrowed_open = 0, keys = 0, subs = 0, passes_frames = 0;
  double key_min_psnr = 1e9, sub_min_psnr = 1e9, sub_mean_psnr = 0, free_sub_min_psnr = 1e9, vs_free_min = 1e9;
  Image a, b, c, x;
  for (const auto& tc : trace) {
    exact.render(tc.camera, x);
    free_run.render_at(tc.camera, tc.time_s, a);
    narrowed.render_at(tc.camera, tc.time_s, b);
    fallback.render_at(tc.camera, tc.time_s, c);
    const FrameStats& n = narrowed.last_stats();
    const double psnr = psnr_rgba8(b, x);
    if (n.key_frame) {
      ++keys;
      key_min_psnr = std::min(key_min_psnr, psnr);
    } else {
      ++subs;
      sub_min_psnr = std::min(sub_min_psnr, psnr);
      sub_mean_psnr += std::min(psnr, 100.0);
    }
    if (!free_run.last_stats().key_frame) free_sub_min_psnr = std::min(free_sub_min_psnr, psnr_rgba8(a, x));
    vs_free_min = std::min(vs_free_min, psnr_rgba8(a, b));
    if (n.window_narrowed) {
      ++narrowed_keys;
      EXPECT_TRUE(n.key_frame);
      EXPECT_LT(n.window, n.planned_window);
      narrowed_to_zero += n.window == 0 ? 1 : 0;
      narrowed_open += n.window > 0 ? 1 : 0;
    }
    EXPECT_LE(n.longest_pass, limit);
    const FrameStats& f = fallback.last_stats();
    EXPECT_TRUE(f.key_frame);
    EXPECT_EQ(f.window, 0);
    EXPECT_GE(f.passes, 3);
    passes_frames += f.passes > 1 ? 1 : 0;
    EXPECT_TRUE(same_bits(c, x)) << "PSNR " << psnr_rgba8(c, x);
  }
  if (subs > 0) sub_mean_psnr /= subs;
  std::cout << "[ info ] exact list " << exact_entries << ", W = 4 lists " << shortest_w4 << ".." << longest_w4
            << ", limit " << limit << "; narrowed run: " << keys << " key frames (" << narrowed_keys << " narrowed, "
            << narrowed_to_zero << " to W = 0), " << subs << " sub-frames; vs the exact render: key frames min "
            << key_min_psnr << " dB, sub-frames mean " << sub_mean_psnr << " min " << sub_min_psnr
            << " dB (unbudgeted run's sub-frames min " << free_sub_min_psnr << " dB); vs the unbudgeted catgs min "
            << vs_free_min << " dB; fallback: " << passes_frames << " frames in passes, equal to exact\n";
  EXPECT_GT(narrowed_keys, 0);
  EXPECT_GT(narrowed_open, 0);  // narrowed to a window that still opens a group
  EXPECT_GT(subs, 0);
  // A key frame is a full render (its split lengths differ from the exact frame's: float rounding).
  EXPECT_GE(key_min_psnr, 60.0);
  // Sub-frames: catgs's own criterion (speculation_test.cpp).
  EXPECT_GE(sub_mean_psnr, 45.0);
  EXPECT_GE(sub_min_psnr, 35.0);
  EXPECT_EQ(passes_frames, static_cast<int>(trace.size()));
}

}  // namespace
}  // namespace catgs
