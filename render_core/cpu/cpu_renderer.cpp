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
  batched_ = false;  // a batch's stage 1 was for the old options (LOD bound, pipeline)
}

void CpuRenderer::render(const Camera& camera, Image& out) {
  validate_camera(camera);
  const bool batched = std::exchange(batched_, false) && same_camera(camera, batched_camera_);
  stats_ = {};
  stats_.stage1_views = batched ? batched_views_ : 1;
  // exact frames split heavy tiles (task splitting, as the CUDA core; renderer.h) and stop each
  // pixel early; vanilla blends a tile whole. Over the budget, in passes (cpu/full_frame.cpp).
  render_full_frame(*model_, chunks_, camera, options_.pipeline, options_, true, {projected_, list_, ranges_, slices_},
                    out, stats_, batched);
}

bool CpuRenderer::shares_stage1_with(const Renderer& other) const {
  const auto* o = dynamic_cast<const CpuRenderer*>(&other);
  return o && o->model_ == model_ && o->options_.pipeline == options_.pipeline &&
         o->options_.lod_error_px == options_.lod_error_px;
}

void CpuRenderer::preprocess_together(const std::vector<Renderer*>& renderers, const std::vector<Camera>& cameras) {
  auto refuse = [](const std::string& why) { throw std::invalid_argument("preprocess_together: " + why); };
  if (renderers.empty() || renderers[0] != this) refuse("the batch's first renderer must be the one asked");
  if (cameras.size() != renderers.size())
    refuse(std::to_string(renderers.size()) + " renderers but " + std::to_string(cameras.size()) + " cameras");
  std::vector<CpuRenderer*> views;
  std::vector<ProjectedGaussians*> outs;
  for (std::size_t k = 0; k < renderers.size(); ++k) {
    auto* r = dynamic_cast<CpuRenderer*>(renderers[k]);
    if (!r || !shares_stage1_with(*r)) refuse("renderer " + std::to_string(k) + " cannot share this one's stage 1");
    if (std::find(views.begin(), views.end(), r) != views.end())
      refuse("renderer " + std::to_string(k) + " appears twice");
    validate_camera(cameras[k]);
    views.push_back(r);
    outs.push_back(&r->projected_);
  }
  preprocess_batch(*model_, chunks_, cameras, options_.pipeline, outs, options_.lod_error_px);
  for (std::size_t k = 0; k < views.size(); ++k) {
    views[k]->batched_ = true;
    views[k]->batched_camera_ = cameras[k];
    views[k]->batched_views_ = static_cast<int>(views.size());
  }
}

}  // namespace catgs::cpu
