// A whole frame through the exact or vanilla stages, in one pass or, over the render-list budget,
// in passes of tiles (renderer/render_passes.h; issue 35). Mirrors the CUDA core's render_full
// and its catgs key frames without a window (cuda_renderer.cpp), which run the same driver.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "cpu/cpu_renderer.h"
#include "renderer/render_passes.h"

namespace catgs::cpu {

namespace {
// Adds the entries that changed a pixel and their distinct Gaussians to stats.
void count_changes(const RenderList& list, const std::vector<std::uint8_t>& changed, FrameStats& stats) {
  std::vector<std::uint32_t> gaussians;
  for (std::size_t k = 0; k < changed.size(); ++k)
    if (changed[k]) gaussians.push_back(list.values[k]);
  stats.entries_changing_pixels += gaussians.size();
  std::sort(gaussians.begin(), gaussians.end());
  stats.gaussians_changing_pixels +=
      static_cast<std::size_t>(std::unique(gaussians.begin(), gaussians.end()) - gaussians.begin());
}
}  // namespace

void render_full_frame(const GaussianModel& model, const std::vector<fm::ChunkBounds>& chunks, const Camera& camera,
                       Pipeline stages, const RenderOptions& options, bool early_termination,
                       const FrameBuffers& buffers, Image& out, FrameStats& stats) {
  ProjectedGaussians& projected = buffers.projected;
  RenderList& list = buffers.list;
  const TileGrid grid = TileGrid::of(camera.width, camera.height);
  const SpeculationParams& sp = options.speculation;
  const auto start = clock::now();
  stats.preprocess_ms = stats.keys_ms = stats.sort_ms = stats.ranges_ms = stats.rasterize_ms = stats.merge_ms = 0;
  preprocess(model, chunks, camera, stages, projected, fm::kAllTiles, options.lod_error_px, buffers.occlusion);
  // This frame's occlusion map: the rasterizer's opaque points, then their depths.
  std::vector<std::uint32_t> opaque_at;
  if (buffers.tile_depth) {
    buffers.tile_depth->assign(static_cast<std::size_t>(grid.tile_count()), INFINITY);
    opaque_at.assign(static_cast<std::size_t>(grid.tile_count()), UINT32_MAX);
  }
  if (buffers.pixel_depth) buffers.pixel_depth->assign(static_cast<std::size_t>(grid.width) * grid.height, INFINITY);
  stats.entries_behind_opaque = 0;
  if (buffers.depth) *buffers.depth = DepthGrid{};  // vanilla, or no grid asked: none
  stats.preprocess_ms += ms_between(start, clock::now());
  const std::uint64_t entries = count_entries(projected);
  stats.visible = static_cast<std::size_t>(
      std::count_if(projected.tiles_touched.begin(), projected.tiles_touched.end(), [](uint32_t n) { return n > 0; }));
  stats.render_list_length = static_cast<std::size_t>(entries);
  stats.chunks_preprocessed = projected.chunks_kept;

  // Stages 2-5 over the tiles [first, end) of what was pre-processed last, sorted with `packing`.
  // The split length comes from the whole frame's list (`entries` over every tile), so a pass
  // splits its tiles as the single pass would.
  auto draw = [&](const fm::DepthKeyPacking* packing, std::uint32_t first, std::uint32_t end) {
    auto t = clock::now();
    emit_keys(projected, grid, stages, options.list_budget, list);
    stats.keys_ms += ms_between(t, clock::now());
    t = clock::now();
    sort_render_list(list, packing ? *packing : single_sort_packing_of(list, grid));
    stats.sort_ms += ms_between(t, clock::now());
    t = clock::now();
    identify_tile_ranges(list, grid, buffers.ranges);
    stats.ranges_ms += ms_between(t, clock::now());
    t = clock::now();
    if (stages == Pipeline::exact) {
      plan_slices(buffers.ranges, static_cast<std::size_t>(entries), sp.task_splitting && !buffers.changed,
                  buffers.slices, static_cast<std::size_t>(sp.min_slice_entries), first, end);
      double merge_ms = 0;
      if (buffers.changed) buffers.changed->assign(list.values.size(), 0);
      rasterize_slices(projected, list, buffers.slices, grid, early_termination, options.background, out, &merge_ms,
                       first, end, buffers.tile_depth ? opaque_at.data() : nullptr,
                       buffers.changed ? buffers.changed->data() : nullptr,
                       buffers.tile_depth && buffers.pixel_depth ? buffers.pixel_depth->data() : nullptr);
      if (buffers.changed) {
        count_changes(list, *buffers.changed, stats);
        if (first == 0 && end == static_cast<std::uint32_t>(grid.tile_count()))
          count_hidden(model, chunks, camera, options.lod_error_px, projected, list, buffers.ranges, stats);
      }
      if (buffers.tile_depth)
        stats.entries_behind_opaque +=
            occlusion_map(projected, list, buffers.ranges, opaque_at.data(), first, end, buffers.tile_depth->data());
      stats.merge_ms += merge_ms;
      stats.slices = buffers.slices.size();
      if (buffers.depth && options.depth_grid_cell > 0)
        depth_grid(projected, list, buffers.ranges, grid, options.depth_grid_cell, first, end, *buffers.depth);
    } else {
      rasterize(projected, list, buffers.ranges, grid, options.background, out, first, end);
      stats.slices = static_cast<std::size_t>(end - first);
    }
    stats.rasterize_ms += ms_between(t, clock::now());
  };

  if (entries <= options.list_budget.max_entries(camera.width, camera.height, kBytesPerListEntry)) {
    draw(nullptr, 0, static_cast<std::uint32_t>(grid.tile_count()));
    stats.passes = 1;
    stats.longest_pass = stats.render_list_length;
  } else {
    // Every pass sorts with the whole frame's key (the depth range of all its listed Gaussians),
    // so ties in the quantised depth fall as in one pass.
    const fm::DepthKeyPacking packing = single_sort_packing_of(projected, grid);
    const PassesDrawn done = draw_in_passes(
        options.list_budget, camera.width, camera.height, kBytesPerListEntry, entries, stats.visible,
        [&](const fm::TileRect& region) {
          const auto t = clock::now();
          preprocess(model, chunks, camera, stages, projected, region, options.lod_error_px, buffers.occlusion);
          stats.preprocess_ms += ms_between(t, clock::now());
          return count_entries(projected);
        },
        [&](const fm::TileRect& region, std::uint64_t) {
          draw(&packing, first_tile(region, grid.tiles_x), end_tile(region, grid.tiles_x));
        });
    stats.passes = done.passes;
    stats.longest_pass = static_cast<std::size_t>(done.longest);
  }
  stats.rasterize_ms -= stats.merge_ms;
  stats.total_ms = ms_between(start, clock::now());
}

}  // namespace catgs::cpu
