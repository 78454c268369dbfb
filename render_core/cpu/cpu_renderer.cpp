// The CPU Renderer: runs the five stages and times them.
#include "cpu/cpu_renderer.h"

#include <algorithm>
#include <atomic>
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
  stats_ = {};
  // exact frames split heavy tiles (task splitting, as the CUDA core; renderer.h) and stop each
  // pixel early; vanilla blends a tile whole. Over the budget, in passes (cpu/full_frame.cpp).
  render_full_frame(*model_, chunks_, camera, options_.pipeline, options_, true, {projected_, list_, ranges_, slices_},
                    out, stats_);
}

}  // namespace catgs::cpu
