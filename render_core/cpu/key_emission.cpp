// Stage 2: render-list key emission (mirrors the CUDA scan + emit kernels).
#include <limits>
#include <stdexcept>
#include <string>

#include "forward_model/occlusion.h"
#include "forward_model/trail.h"
#include "cpu/cpu_renderer.h"
#include "cpu/host_buffer.h"
#include "base/parallel_for.h"

namespace catgs::cpu {

std::uint64_t count_entries(const ProjectedGaussians& projected) {
  std::uint64_t total = 0;
  for (const uint32_t n : projected.tiles_touched) total += n;
  return total;
}

void emit_keys(const ProjectedGaussians& projected, const TileGrid& grid, Pipeline pipeline,
               const RenderListBudget& budget, RenderList& list) {
  const std::size_t n = projected.tiles_touched.size();
  grow_host(list.offsets, n, "emission offsets");
  uint64_t total = 0;
  for (std::size_t i = 0; i < n; ++i) {  // exclusive scan
    list.offsets[i] = total;
    total += projected.tiles_touched[i];
  }
  // Before the list is allocated: the budget bounds what a pathological scene can make us take.
  budget.check(total, grid.width, grid.height, kBytesPerListEntry);
  if (total > std::numeric_limits<uint32_t>::max())
    throw std::length_error("render list of " + std::to_string(total) +
                            " entries exceeds the 32-bit range of tile ranges");
  grow_host(list.keys, total, "render-list keys");
  grow_host(list.values, total, "render-list values");
  list.packing = fm::plain_key_packing();
  const bool exact = pipeline == Pipeline::exact, trail = pipeline == Pipeline::catgs;
  // Occlusion culling's per-entry test, as pre-processing counted (ProjectedGaussians::occlusion).
  const bool hidden = exact && projected.occlusion.cells[0] != nullptr;

  parallel_for(n, 4096, [&](std::size_t i) {
    if (projected.tiles_touched[i] == 0) return;
    const fm::TileRect r = projected.tile_rect[i];
    const fm::TrailTileTest trail_test =
        trail ? fm::make_trail_tile_test(projected.trail_mean0[i], projected.trail_motion[i], projected.trail_conic[i],
                                         projected.q_trail[i])
              : fm::TrailTileTest{};
    const bool per_entry = hidden && fm::tile_count(r) <= fm::kOcclusionEntryTiles;
    uint64_t at = list.offsets[i];
    for (int ty = r.y0; ty < r.y1; ++ty) {
      for (int tx = r.x0; tx < r.x1; ++tx) {
        if (exact && !fm::ellipse_touches_tile(projected.mean2d[i], projected.conic[i], projected.q_max[i], tx, ty,
                                               grid.width, grid.height))
          continue;
        if (trail && !fm::trail_touches_tile(trail_test, tx, ty, grid.width, grid.height)) continue;
        const auto tile = static_cast<uint32_t>(ty * grid.tiles_x + tx);
        if (per_entry && fm::entry_hidden(projected.occlusion, projected.mean2d[i], projected.conic[i],
                                          projected.q_max[i], projected.depth[i], tx, ty, grid.width, grid.height))
          continue;
        list.keys[at] = fm::render_key(tile, projected.depth[i]);
        list.values[at] = static_cast<uint32_t>(i);
        ++at;
      }
    }
  });
}

}  // namespace catgs::cpu
