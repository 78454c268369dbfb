// The CPU Renderer: runs the five stages and times them.
#include "cpu/cpu_renderer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace catgs::cpu {

CpuRenderer::CpuRenderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options)
    : model_(std::move(model)) {
  if (!model_) throw std::invalid_argument("CpuRenderer: null model");
  chunks_ = chunk_bounds_of(*model_);
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
