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
  occlusion_valid_ = false;  // a map of other options (a cut, a pipeline) says nothing now
}

void CpuRenderer::render(const Camera& camera, Image& out) {
  validate_camera(camera);
  stats_ = {};
  // exact frames split heavy tiles (task splitting, as the CUDA core; renderer.h) and stop each
  // pixel early; vanilla blends a tile whole. Over the budget, in passes (cpu/full_frame.cpp).
  FrameBuffers buffers{projected_, list_, ranges_, slices_};
  const bool occlusion = options_.occlusion_culling && options_.pipeline == Pipeline::exact;
  const fm::View view = fm::view_of(camera);
  if (occlusion && occlusion_valid_) {
    buffers.occlusion = fm::occlusion_map(occlusion_depth_.data(), occlusion_view_, view);
    const TileGrid grid = TileGrid::of(camera.width, camera.height);
    occlusion_reproject(buffers.occlusion, view, grid, occlusion_now_);
    buffers.occlusion.now_depth = occlusion_now_.data();
    buffers.occlusion.now_tiles_x = grid.tiles_x;
  }
  stats_.occlusion_map_used = buffers.occlusion.depth != nullptr;
  if (occlusion) buffers.tile_depth = &occlusion_next_;
  if (count_changes_) buffers.changed = &changed_;
  occlusion_valid_ = false;  // until this frame has drawn its own
  render_full_frame(*model_, chunks_, camera, options_.pipeline, options_, true, buffers, out, stats_);
  if (occlusion) {
    std::swap(occlusion_depth_, occlusion_next_);
    occlusion_view_ = view;
    occlusion_valid_ = true;
  }
}

}  // namespace catgs::cpu
