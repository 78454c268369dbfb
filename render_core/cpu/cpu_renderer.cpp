// The CPU Renderer: runs the five stages and times them.
#include "cpu/cpu_renderer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

namespace catgs::cpu {

void parallel_for(std::size_t n, std::size_t grain, const std::function<void(std::size_t)>& fn) {
  if (n == 0) return;
  grain = std::max<std::size_t>(grain, 1);
  const std::size_t chunks = (n + grain - 1) / grain;
  const std::size_t workers = std::min<std::size_t>(chunks, std::max(1u, std::thread::hardware_concurrency()));
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t c; (c = next.fetch_add(1)) < chunks;)
      for (std::size_t i = c * grain, end = std::min(n, i + grain); i < end; ++i) fn(i);
  };
  if (workers <= 1) return work();
  std::vector<std::thread> threads;
  threads.reserve(workers - 1);
  for (std::size_t w = 1; w < workers; ++w) threads.emplace_back(work);
  work();
  for (auto& t : threads) t.join();
}

CpuRenderer::CpuRenderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options)
    : model_(std::move(model)) {
  if (!model_) throw std::invalid_argument("CpuRenderer: null model");
  chunks_ = fm::chunk_bounds(*model_);
  set_options(options);
}

void CpuRenderer::set_options(const RenderOptions& options) {
  if (options.pipeline == Pipeline::catgs)
    throw std::invalid_argument("the catgs pipeline is not implemented in the CPU renderer yet");
  options_ = options;
}

void CpuRenderer::render(const Camera& camera, Image& out) {
  validate_camera(camera);
  using clock = std::chrono::steady_clock;
  auto ms = [](clock::time_point a, clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const TileGrid grid = TileGrid::of(camera.width, camera.height);
  const auto t0 = clock::now();
  preprocess(*model_, chunks_, camera, options_.pipeline, projected_);
  const auto t1 = clock::now();
  emit_keys(projected_, grid, options_.pipeline, options_.list_budget, list_);
  const auto t2 = clock::now();
  sort_render_list(list_, single_sort_packing_of(list_, grid));
  const auto t3 = clock::now();
  identify_tile_ranges(list_, grid, ranges_);
  const auto t4 = clock::now();
  if (options_.pipeline == Pipeline::exact) {  // task splitting, as the CUDA core (renderer.h)
    const SpeculationParams& sp = options_.speculation;
    plan_slices(ranges_, list_.keys.size(), sp.task_splitting, slices_, static_cast<std::size_t>(sp.min_slice_entries));
    rasterize_slices(projected_, list_, slices_, grid, true, options_.background, out);
  } else {
    rasterize(projected_, list_, ranges_, grid, options_.background, out);
  }
  const auto t5 = clock::now();

  stats_ = {};
  stats_.visible = static_cast<std::size_t>(std::count_if(
      projected_.tiles_touched.begin(), projected_.tiles_touched.end(), [](uint32_t n) { return n > 0; }));
  stats_.render_list_length = list_.keys.size();
  stats_.preprocess_ms = ms(t0, t1);
  stats_.keys_ms = ms(t1, t2);
  stats_.sort_ms = ms(t2, t3);
  stats_.ranges_ms = ms(t3, t4);
  stats_.rasterize_ms = ms(t4, t5);
  stats_.total_ms = ms(t0, t5);
}

}  // namespace catgs::cpu
