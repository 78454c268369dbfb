// Render-list passes (render_passes.h): the regions of a frame over the budget, and the order the
// cores draw them in.
#include "renderer/render_passes.h"

#include <algorithm>
#include <string>
#include <vector>

namespace catgs {

namespace {

// `r` cut into `parts` runs of about equal size: bands of its rows, or, for one row, runs of its
// tiles (so every region stays one run of tile ids). Pushed last first onto `todo`, a stack, so
// the regions come off it top to bottom.
void cut(const fm::TileRect& r, std::uint64_t parts, std::vector<fm::TileRect>& todo) {
  const bool rows = r.y1 - r.y0 > 1;
  const int lo = rows ? r.y0 : r.x0, span = rows ? r.y1 - r.y0 : r.x1 - r.x0;
  const int n = static_cast<int>(std::min<std::uint64_t>(std::max<std::uint64_t>(parts, 2), span));
  for (int k = n; k-- > 0;) {
    const int a = lo + static_cast<int>(static_cast<long long>(span) * k / n);
    const int b = lo + static_cast<int>(static_cast<long long>(span) * (k + 1) / n);
    todo.push_back(rows ? fm::TileRect{r.x0, a, r.x1, b} : fm::TileRect{a, r.y0, b, r.y1});
  }
}

}  // namespace

PassesDrawn draw_in_passes(const RenderListBudget& budget, int width, int height, std::uint64_t bytes_per_entry,
                           std::uint64_t entries, std::uint64_t listed,
                           const std::function<std::uint64_t(const fm::TileRect&)>& count,
                           const std::function<void(const fm::TileRect&, std::uint64_t)>& draw) {
  budget.check_passes(entries, listed, width, height, bytes_per_entry);
  const std::uint64_t limit = budget.max_entries(width, height, bytes_per_entry);
  std::vector<fm::TileRect> todo;
  // The first cut assumes the entries spread evenly over the rows; real views crowd some rows
  // (the horizon), whose bands are cut again when counted over.
  cut(whole_grid(width, height), (entries + limit - 1) / limit, todo);
  PassesDrawn done;
  while (!todo.empty()) {
    const fm::TileRect region = todo.back();
    todo.pop_back();
    const std::uint64_t n = count(region);
    ++done.counted;
    if (n > limit) {
      if (fm::tile_count(region) == 1)
        throw budget.error(entries, width, height, bytes_per_entry,
                           "tile (" + std::to_string(region.x0) + ", " + std::to_string(region.y0) + ") alone lists " +
                               std::to_string(n) + " entries, more than a pass may hold");
      cut(region, (n + limit - 1) / limit, todo);
      continue;
    }
    if (static_cast<std::uint64_t>(done.passes) >= budget.max_passes)
      throw budget.error(entries, width, height, bytes_per_entry,
                         "more than " + std::to_string(budget.max_passes) + " passes of the budget would be needed");
    draw(region, n);
    ++done.passes;
    done.longest = std::max(done.longest, n);
  }
  return done;
}

}  // namespace catgs
