// Renderer's default colour-converted render: host frame, CPU conversion (yuv420.h).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <string>
#include <stdexcept>

#include "renderer/renderer.h"

namespace catgs {

// Pipeline names (here, not in the factory: the server's message checks use them without the
// cores).
Pipeline parse_pipeline(const std::string& name) {
  if (name == "vanilla") return Pipeline::vanilla;
  if (name == "exact") return Pipeline::exact;
  if (name == "catgs") return Pipeline::catgs;
  throw std::invalid_argument("unknown pipeline '" + name + "' (vanilla, exact or catgs)");
}

const char* pipeline_name(Pipeline p) {
  switch (p) {
    case Pipeline::vanilla:
      return "vanilla";
    case Pipeline::exact:
      return "exact";
    case Pipeline::catgs:
      return "catgs";
  }
  return "?";
}

double Renderer::render_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) {
  check_yuv420_target("render_yuv420_at", out, camera.width, camera.height);
  if (out.memory != MemoryKind::host)
    throw std::invalid_argument("render_yuv420_at: the " + name() + " renderer cannot write a device target");
  render_at(camera, time_s, yuv_source_);
  const auto t0 = std::chrono::steady_clock::now();
  rgba_to_yuv420_bt709(yuv_source_.rgba8.data(), yuv_source_.width, yuv_source_.height, yuv_source_.width * 4, out);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void Renderer::begin_frame() {
  if (frame_begun_) throw std::logic_error(name() + " renderer: a frame is begun already (finish_yuv420 first)");
  frame_begun_ = true;
}

void Renderer::end_frame() {
  if (!frame_begun_) throw std::logic_error(name() + " renderer: finish_yuv420 without begin_yuv420_at");
  frame_begun_ = false;
}

void Renderer::begin_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) {
  begin_frame();
  try {
    begun_convert_ms_ = render_yuv420_at(camera, time_s, out);
  } catch (...) {
    frame_begun_ = false;  // nothing to finish
    throw;
  }
}

double Renderer::finish_yuv420() {
  end_frame();
  return begun_convert_ms_;
}

std::uint64_t RenderListBudget::max_entries(int width, int height, std::uint64_t bytes_per_entry) const {
  // Tile counts come from validated cameras (sides <= kMaxImageSide): the products fit 64 bits.
  const std::uint64_t tiles =
      static_cast<std::uint64_t>((width + 15) / 16) * static_cast<std::uint64_t>((height + 15) / 16);
  std::uint64_t entries =
      max_entries_per_tile > UINT64_MAX / std::max<std::uint64_t>(tiles, 1) ? UINT64_MAX : max_entries_per_tile * tiles;
  entries = std::max(entries, min_entries);
  entries = std::min(entries, max_bytes / std::max<std::uint64_t>(bytes_per_entry, 1));
  return std::min<std::uint64_t>(entries, 0xffffffffull);  // 32-bit tile ranges and values
}

void RenderListBudget::check(std::uint64_t entries, int width, int height, std::uint64_t bytes_per_entry) const {
  if (entries <= max_entries(width, height, bytes_per_entry)) return;
  throw error(entries, width, height, bytes_per_entry, "the scene has Gaussians that cover much of the screen");
}

void RenderListBudget::check_reach(std::uint64_t entries, std::uint64_t listed, int width, int height,
                                   std::uint64_t bytes_per_entry) const {
  if (entries <= max_entries(width, height, bytes_per_entry)) return;
  // Giant Gaussians: on average each listed one reaches more than 1 / giant_share of the tiles,
  // entries / listed > tiles / giant_share. (The products fit 64 bits: a Gaussian lists each tile
  // at most once, so entries <= listed x tiles < 2^32 x 2^18, and giant_share is small.)
  const auto tiles = static_cast<std::uint64_t>((width + 15) / 16) * static_cast<std::uint64_t>((height + 15) / 16);
  if (giant_share > 0 && entries * giant_share > listed * tiles)
    throw error(entries, width, height, bytes_per_entry, "the scene has Gaussians that cover much of the screen");
}

void RenderListBudget::check_passes(std::uint64_t entries, std::uint64_t listed, int width, int height,
                                    std::uint64_t bytes_per_entry) const {
  const std::uint64_t limit = max_entries(width, height, bytes_per_entry);
  if (entries <= limit) return;
  check_reach(entries, listed, width, height, bytes_per_entry);
  // Passes hold disjoint parts of the list: fewer than entries / limit of them cannot hold it.
  if (limit == 0 || max_passes <= 1)  // passes are off: refused as a single pass is
    throw error(entries, width, height, bytes_per_entry, "the scene has Gaussians that cover much of the screen");
  if ((entries - 1) / limit >= max_passes)
    throw error(entries, width, height, bytes_per_entry,
                "more than " + std::to_string(max_passes) + " passes of the budget would be needed");
}

RenderBudgetError RenderListBudget::error(std::uint64_t entries, int width, int height, std::uint64_t bytes_per_entry,
                                          const std::string& why) const {
  const std::uint64_t limit = max_entries(width, height, bytes_per_entry);
  return RenderBudgetError(
      "render list of " + std::to_string(entries) + " entries (" + std::to_string(entries * bytes_per_entry >> 20) +
      " MiB) exceeds the render-list budget of " + std::to_string(limit) + " entries for a " + std::to_string(width) +
      "x" + std::to_string(height) + " frame (" + std::to_string(max_entries_per_tile) + " a tile, at most " +
      std::to_string(max_bytes >> 20) + " MiB): " + why);
}

}  // namespace catgs
