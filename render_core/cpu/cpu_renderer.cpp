// The CPU Renderer: runs the five stages and times them.
#include "cpu/cpu_renderer.h"
#include "cpu/host_buffer.h"

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

void reserve_frame_buffers(std::size_t gaussians, const BufferShape& shape, ProjectedGaussians& projected,
                           RenderList& list) {
  const std::size_t n_projected = projected.mean2d.size(), n_offsets = list.offsets.size();
  const std::size_t n_keys = list.keys.size(), n_values = list.values.size();
  projected.resize(gaussians);
  grow_host(list.offsets, gaussians, "emission offsets");
  grow_host(list.keys, static_cast<std::size_t>(shape.list_entries), "render-list keys");
  grow_host(list.values, static_cast<std::size_t>(shape.list_entries), "render-list values");
  // Held, not filled: the sizes stay what the last frame left.
  projected.resize(n_projected);
  list.offsets.resize(n_offsets);
  list.keys.resize(n_keys);
  list.values.resize(n_values);
}

BufferShape frame_buffer_shape(const ProjectedGaussians& projected, const RenderList& list) {
  return {projected.mean2d.capacity(), std::min(list.keys.capacity(), list.values.capacity())};
}

void CpuRenderer::reserve_buffers(int width, int height, const BufferShape& shape) {
  (void)width, (void)height;
  reserve_frame_buffers(model_->size(), shape, projected_, list_);
}

BufferShape CpuRenderer::buffer_shape() const { return frame_buffer_shape(projected_, list_); }

void CpuRenderer::render(const Camera& camera, Image& out) {
  validate_camera(camera);
  stats_ = {};
  // exact frames split heavy tiles (task splitting, as the CUDA core; renderer.h) and stop each
  // pixel early; vanilla blends a tile whole. Over the budget, in passes (cpu/full_frame.cpp).
  FrameBuffers buffers{projected_, list_, ranges_, slices_};
  const bool occlusion = options_.occlusion_culling && options_.pipeline == Pipeline::exact;
  const fm::View view = fm::view_of(camera);
  if (occlusion && occlusion_valid_) {
    buffers.occlusion =
        occlusion_reproject(occlusion_depth_.data(), occlusion_view_, view, occlusion_now_, occlusion_cells_);
  }
  stats_.occlusion_map_used = buffers.occlusion.cells[0] != nullptr;
  if (occlusion) {
    buffers.tile_depth = &occlusion_tiles_;
    buffers.pixel_depth = &occlusion_next_;
  }
  if (count_changes_) buffers.changed = &changed_;
  buffers.depth = &depth_grid_;
  occlusion_valid_ = false;  // until this frame has drawn its own
  render_full_frame(*model_, chunks_, camera, options_.pipeline, options_, true, buffers, out, stats_);
  if (occlusion) {
    std::swap(occlusion_depth_, occlusion_next_);
    occlusion_view_ = view;
    occlusion_valid_ = true;
  }
}

}  // namespace catgs::cpu
