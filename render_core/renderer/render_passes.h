// Render-list passes (issue 35; the rule is RenderListBudget's, renderer.h): a frame whose list is
// over the budget is drawn in passes of tiles, each pre-processed, listed, sorted and rasterized
// on its own within the budget, into the same image. Both cores run this one driver with their
// own stages, so they split a frame the same way from the same counts.
#pragma once

#include <cstdint>
#include <functional>

#include "forward_model/forward_model.h"
#include "renderer/renderer.h"

namespace catgs {

// What a frame drawn in passes took: the passes drawn, the longest pass's list, and the regions
// counted (passes + those found over the budget and split).
struct PassesDrawn {
  int passes = 0;
  std::uint64_t longest = 0;
  int counted = 0;
};

// Draws a width x height frame of `entries` list entries from `listed` Gaussians (those with
// entries), over budget.max_entries(width, height, bytes_per_entry), in passes:
//  1. budget.check_passes(...) refuses giant Gaussians and frames of too many passes
//     (RenderBudgetError);
//  2. the frame's tile rows are cut into ceil(entries / max_entries) equal bands;
//  3. for each region in top-to-bottom order, `count(region)` pre-processes the region (the
//     frame's camera, each Gaussian's tiles clipped to the region: fm::clip_tile_rect) and returns
//     its list length; a region within the budget is then drawn by `draw(region, length)` (list,
//     sort, ranges and rasterize its tiles only, from what count() left), one over it is cut
//     again, into ceil(length / max_entries) (at least 2) bands of its rows, or, for one row,
//     runs of its tiles. A region is always whole rows or part of one row, so its tile ids are
//     one run: [y0 * tiles_x + x0, (y1 - 1) * tiles_x + x1).
// Throws RenderBudgetError when a single tile's list is over the budget (no pass can hold it) or
// more than budget.max_passes passes would be drawn, and what count() and draw() throw. The image
// holds the passes drawn before a throw.
PassesDrawn draw_in_passes(const RenderListBudget& budget, int width, int height, std::uint64_t bytes_per_entry,
                           std::uint64_t entries, std::uint64_t listed,
                           const std::function<std::uint64_t(const fm::TileRect&)>& count,
                           const std::function<void(const fm::TileRect&, std::uint64_t)>& draw);

// The first and one-past-last tile id of a pass's region on a grid `tiles_x` tiles wide.
inline std::uint32_t first_tile(const fm::TileRect& r, int tiles_x) {
  return static_cast<std::uint32_t>(r.y0 * tiles_x + r.x0);
}
inline std::uint32_t end_tile(const fm::TileRect& r, int tiles_x) {
  return static_cast<std::uint32_t>((r.y1 - 1) * tiles_x + r.x1);
}
// The whole grid as a region.
inline fm::TileRect whole_grid(int width, int height) {
  return {0, 0, (width + fm::kTileSize - 1) / fm::kTileSize, (height + fm::kTileSize - 1) / fm::kTileSize};
}

}  // namespace catgs
