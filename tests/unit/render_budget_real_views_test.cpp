// Issue 35: no view of a real scene is refused by the render-list budget (default RenderListBudget):
// the 7 M-Gaussian city (13 tumblewood copies x10, as `catgs-scene tile --scale 10 --radius-sq 4
// --up 0,-1,0`), tumblewood x10 and flowers, on the three real camera paths (cameras.json fitted
// to each scene as `catgs-scene trace`), at 640x360 .. 3840x2160, vanilla, exact and catgs.
//
// What it covers, and how it stays under ~2 minutes on 2 cores (a CPU pre-processing of the city
// takes ~2.7 s, a W = 4 trail pre-processing ~10 s at 720p and ~50 s at 4K):
// - The decision, without rasterizing: each probe runs the core's own stage functions and its
//   pass driver as the renderers do (cpu/full_frame.cpp render_full_frame for vanilla and exact,
//   cpu/speculative_renderer.cpp key_frame for catgs): pre-process, count the list, hold it
//   against the budget; over it, catgs narrows its window (SpeculationPlanner::narrower_window,
//   check_reach) and exact/vanilla run draw_in_passes, pre-processing and counting every region
//   (only stages 2-5 of each pass are left out). A RenderBudgetError anywhere fails the test.
//   catgs probes W = 4 (the longest list the planner can ask for) over the trace's own next
//   poses (what a perfect predictor would give).
// - Poses: tumblewood and flowers 2 per path (at 0.3 and 0.7 of it), every size and pipeline
//   (tumblewood's catgs at 640x360, 1280x720 and 3840x2160); the city 1 per path (the middle), vanilla and exact at 640x360 and 3840x2160 (the
//   smallest budget, 16 M entries, and the one the bytes cap sets, 153 M) and catgs at 1280x720
//   (issue 35's refused case: 59.35 M entries against 59.0 M on the GPU host).
// - Full renders with the real renderers (CpuRenderer, SpeculativeRenderer, default budget) of
//   tumblewood and flowers at 640x360: 4 consecutive frames per path and pipeline.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "renderer/render_passes.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"
#include "scene_tools/city.h"
#include "test_data.h"

namespace catgs {
namespace {

struct Probe {
  std::uint64_t entries = 0, limit = 0;
  int passes = 1, window = 0;
  double reach = 0;  // entries / listed, in tiles
};

std::uint64_t listed(const cpu::ProjectedGaussians& p) {
  return static_cast<std::uint64_t>(
      std::count_if(p.tiles_touched.begin(), p.tiles_touched.end(), [](uint32_t n) { return n > 0; }));
}

// render_full_frame's decision (vanilla, exact, catgs W = 0), stages 2-5 left out.
Probe probe_full(const GaussianModel& m, const std::vector<fm::ChunkBounds>& chunks, const Camera& cam, Pipeline p,
                 const RenderListBudget& budget, cpu::ProjectedGaussians& pg) {
  Probe r;
  cpu::preprocess(m, chunks, cam, p, pg);
  r.entries = cpu::count_entries(pg);
  r.limit = budget.max_entries(cam.width, cam.height, cpu::kBytesPerListEntry);
  r.reach = static_cast<double>(r.entries) / static_cast<double>(std::max<std::uint64_t>(1, listed(pg)));
  if (r.entries <= r.limit) return r;
  r.passes = draw_in_passes(
                 budget, cam.width, cam.height, cpu::kBytesPerListEntry, r.entries, listed(pg),
                 [&](const fm::TileRect& region) {
                   cpu::preprocess(m, chunks, cam, p, pg, region);
                   return cpu::count_entries(pg);
                 },
                 [](const fm::TileRect&, std::uint64_t) {})
                 .passes;
  return r;
}

// SpeculativeRenderer::key_frame's decision from W = 4 over `path` (key camera first).
Probe probe_catgs(const GaussianModel& m, const std::vector<fm::ChunkBounds>& chunks, const std::vector<Camera>& path,
                  const RenderListBudget& budget, cpu::ProjectedGaussians& pg) {
  const SpeculationParams sp;
  const Camera& cam = path.front();
  const std::uint64_t limit = budget.max_entries(cam.width, cam.height, cpu::kBytesPerListEntry);
  Probe r;
  for (int w = sp.initial_window; w > 0; w = SpeculationPlanner::narrower_window(w)) {
    cpu::speculative_preprocess(m, chunks, std::vector<Camera>(path.begin(), path.begin() + w + 1),
                                trail_widening(sp, w), pg);
    r.entries = cpu::count_entries(pg);
    r.limit = limit;
    r.window = w;
    r.reach = static_cast<double>(r.entries) / static_cast<double>(std::max<std::uint64_t>(1, listed(pg)));
    if (r.entries <= limit) return r;
    budget.check_reach(r.entries, listed(pg), cam.width, cam.height, cpu::kBytesPerListEntry);
  }
  Probe full = probe_full(m, chunks, cam, Pipeline::exact, budget, pg);
  full.window = 0;
  return full;
}

struct Path {
  const char* name;
  const char* cameras;
};
const Path kPaths[] = {{"bicycle", "traces/mipnerf360_bicycle.cameras.json"},
                       {"train", "traces/tandt_train.cameras.json"},
                       {"flowers", "traces/flowers_sh3.cameras.json"}};
const std::pair<int, int> kSizes[] = {{640, 360}, {1280, 720}, {1920, 1080}, {3840, 2160}};

struct Tally {
  int probes = 0, over = 0, narrowed = 0, multi_pass = 0, max_passes = 1;
  double max_ratio = 0, max_reach_share = 0;  // entries / limit; reach / (tiles / giant_share)
  void add(const Probe& p, const Camera& cam, bool catgs) {
    ++probes;
    over += p.entries > p.limit || (catgs && p.window < 4) ? 1 : 0;
    narrowed += catgs && p.window < 4 ? 1 : 0;
    multi_pass += p.passes > 1 ? 1 : 0;
    max_passes = std::max(max_passes, p.passes);
    max_ratio = std::max(max_ratio, static_cast<double>(p.entries) / static_cast<double>(p.limit));
    const double tiles = ((cam.width + 15) / 16) * ((cam.height + 15) / 16);
    max_reach_share =
        std::max(max_reach_share, p.reach / (tiles / static_cast<double>(RenderListBudget{}.giant_share)));
  }
};

// Probes `m` on every path at the poses `fractions` of it, the sizes and pipelines asked for.
void probe_scene(const char* scene, const GaussianModel& m, const std::vector<double>& fractions,
                 const std::vector<std::pair<int, int>>& full_sizes,
                 const std::vector<std::pair<int, int>>& catgs_sizes, Tally& tally) {
  const RenderListBudget budget;  // the defaults, as the server's
  const auto chunks = chunk_bounds_of(m);
  cpu::ProjectedGaussians pg;
  for (const Path& path : kPaths) {
    const std::string file = test::data_file(path.cameras);
    ASSERT_FALSE(file.empty()) << path.cameras;
    const Trace trace =
        fit_trace_to_scene(load_inria_cameras(file), m, {0.0f, -1.0f, 0.0f}, 0.6f, 120.0, 0.5, 1280, 720);
    for (const double f : fractions) {
      const auto k = static_cast<std::size_t>(f * static_cast<double>(trace.size() - 5));
      for (const auto& [w, h] : full_sizes)
        for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact}) {
          const Camera cam = trace[k].camera.rescaled(w, h);
          SCOPED_TRACE(std::string(scene) + " " + path.name + " " + pipeline_name(p) + " " + std::to_string(w));
          Probe r;
          ASSERT_NO_THROW(r = probe_full(m, chunks, cam, p, budget, pg));
          tally.add(r, cam, false);
          std::printf("[ info ] %s %s frame %zu %dx%d %s: %llu entries (%.2f of the budget), %d pass(es)\n", scene,
                      path.name, k, w, h, pipeline_name(p), static_cast<unsigned long long>(r.entries),
                      static_cast<double>(r.entries) / static_cast<double>(r.limit), r.passes);
        }
      for (const auto& [w, h] : catgs_sizes) {
        std::vector<Camera> cams;
        for (std::size_t j = 0; j <= 4; ++j) cams.push_back(trace[k + j].camera.rescaled(w, h));
        SCOPED_TRACE(std::string(scene) + " " + path.name + " catgs " + std::to_string(w));
        Probe r;
        ASSERT_NO_THROW(r = probe_catgs(m, chunks, cams, budget, pg));
        tally.add(r, cams[0], true);
        std::printf("[ info ] %s %s frame %zu %dx%d catgs: W = %d, %llu entries (%.2f of the budget), %d pass(es)\n",
                    scene, path.name, k, w, h, r.window, static_cast<unsigned long long>(r.entries),
                    static_cast<double>(r.entries) / static_cast<double>(r.limit), r.passes);
      }
    }
  }
}

// A few consecutive frames with the real renderers and the default budget.
void render_frames(const char* scene, std::shared_ptr<const GaussianModel> m) {
  for (const Path& path : kPaths) {
    const Trace trace = fit_trace_to_scene(load_inria_cameras(test::data_file(path.cameras)), *m, {0.0f, -1.0f, 0.0f},
                                           0.6f, 120.0, 0.5, 640, 360);
    for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact, Pipeline::catgs}) {
      SCOPED_TRACE(std::string(scene) + " " + path.name + " " + pipeline_name(p));
      RenderOptions o;
      o.pipeline = p;
      auto r = make_renderer("cpu", m, o);
      Image out;
      const std::size_t k0 = trace.size() / 2;
      for (std::size_t k = k0; k < k0 + 4; ++k) ASSERT_NO_THROW(r->render_at(trace[k].camera, trace[k].time_s, out));
    }
  }
}

TEST(RenderBudgetRealViews, NoRealViewIsRefused) {
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  CATGS_REQUIRE_DATA(flowers_file, "scenes/flowers_sh3.ply");
  for (const Path& path : kPaths) {
    CATGS_REQUIRE_DATA(cameras, path.cameras);
  }
  std::vector<std::pair<int, int>> all(std::begin(kSizes), std::end(kSizes));
  Tally tally;
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };

  auto flowers = std::make_shared<GaussianModel>(load_scene(flowers_file));
  probe_scene("flowers", *flowers, {0.3, 0.7}, all, all, tally);
  render_frames("flowers", flowers);
  std::printf("[ info ] flowers done at %.1f s\n", elapsed());

  const GaussianModel base = load_scene(tumblewood);
  auto tumble = std::make_shared<GaussianModel>(base);
  scale_scene(*tumble, 10.0f);
  probe_scene("tumblewood_x10", *tumble, {0.3, 0.7}, all, {{640, 360}, {1280, 720}, {3840, 2160}}, tally);
  render_frames("tumblewood_x10", tumble);
  tumble.reset();
  std::printf("[ info ] tumblewood done at %.1f s\n", elapsed());

  CityParams city_params;  // 13 copies, x10
  city_params.up = {0.0f, -1.0f, 0.0f};
  const GaussianModel city = tile_scene(base, city_params);
  ASSERT_EQ(city.size(), 13 * base.size());
  probe_scene("city13", city, {0.5}, {{640, 360}, {3840, 2160}}, {{1280, 720}}, tally);
  std::printf("[ info ] city done at %.1f s\n", elapsed());

  std::printf(
      "[ info ] %d probes: %d over the budget at first, %d catgs windows narrowed, %d in passes (at most %d); "
      "largest list %.2f x its budget; largest average reach %.3f x the giant-Gaussian threshold\n",
      tally.probes, tally.over, tally.narrowed, tally.multi_pass, tally.max_passes, tally.max_ratio,
      tally.max_reach_share);
  // The giant-Gaussian rule stays clear of real views (measured: at most 0.23 of its threshold).
  EXPECT_LT(tally.max_reach_share, 0.5);
}

}  // namespace
}  // namespace catgs
