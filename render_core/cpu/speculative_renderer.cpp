// The catgs pipeline on the CPU (paper sec. 3; docs/DESIGN.md "Speculation"): key frames
// pre-process a whole speculation window once (trails, frustum cache, sorted list, tile ranges,
// slices); sub-frames recompute only per-Gaussian features of the cached set at their own pose and
// rasterize from the key frame's list. A sub-frame whose Gaussians leave their trails becomes a key
// frame.
#include <algorithm>
#include <chrono>

#include "cpu/cpu_renderer.h"

namespace catgs::cpu {

SpeculativeRenderer::SpeculativeRenderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options)
    : model_(std::move(model)) {
  if (!model_) throw std::invalid_argument("SpeculativeRenderer: null model");
  chunks_ = chunk_bounds_of(*model_);
  set_options(options);
}

void SpeculativeRenderer::set_options(const RenderOptions& options) {
  if (options.pipeline != Pipeline::catgs)
    throw std::invalid_argument("SpeculativeRenderer runs the catgs pipeline only");
  planner_.set_params(options.speculation);
  options_ = options;
}

void SpeculativeRenderer::reserve_buffers(int width, int height, const BufferShape& shape) {
  (void)width, (void)height;
  reserve_frame_buffers(model_->size(), shape, projected_, list_);
}

BufferShape SpeculativeRenderer::buffer_shape() const { return frame_buffer_shape(projected_, list_); }

void SpeculativeRenderer::render(const Camera& camera, Image& out) { render_at(camera, planner_.advance_clock(), out); }

bool SpeculativeRenderer::key_frame(const Camera& camera, Image& out) {
  const SpeculationParams& sp = options_.speculation;
  const auto t0 = clock::now();
  // Plan the window from the predicted path (never from future input): M over one frame, W.
  const int planned =
      planner_.window_wanted()
          ? planner_.window_for(max_screen_motion(*model_, chunks_, camera, planner_.next_camera(camera),
                                                  sp.depth_threshold, options_.lod_error_px))
          : 0;
  // A window whose trail list is over the budget is narrowed (issue 35), as the CUDA core does
  // from the same counts: its list shrinks toward the exact list of W = 0.
  const std::uint64_t limit = options_.list_budget.max_entries(camera.width, camera.height, kBytesPerListEntry);
  int window = planned;
  for (; window > 0; window = SpeculationPlanner::narrower_window(window)) {
    speculative_preprocess(*model_, chunks_, planner_.path(camera, window), trail_widening(sp, window), projected_,
                           options_.lod_error_px);
    const std::uint64_t entries = count_entries(projected_);
    if (entries <= limit) break;
    // Giant Gaussians are refused at once: no window would make their list fit.
    const auto listed = static_cast<std::uint64_t>(std::count_if(
        projected_.tiles_touched.begin(), projected_.tiles_touched.end(), [](uint32_t n) { return n > 0; }));
    options_.list_budget.check_reach(entries, listed, camera.width, camera.height, kBytesPerListEntry);
  }
  const double planning_ms = ms_between(t0, clock::now());
  // The group's sub-frames keep this key frame's LOD cut (their Gaussians are its list's).
  key_cut_ = fm::lod_cut(model_->lod, fm::view_of(camera), options_.lod_error_px);
  if (window == 0) {
    // Without a window the frame is rendered in full by the exact pipeline's stages (its list is
    // the one-pose trail's, built without the trail machinery), in passes over the budget; it
    // opens no group.
    render_full_frame(*model_, chunks_, camera, Pipeline::exact, options_, sp.early_termination,
                      {projected_, list_, ranges_, slices_}, out, stats_);
    stats_.preprocess_ms += planning_ms;
    key_visible_ = stats_.visible;
    cached_.clear();
    planner_.start_group(camera, 0);
  } else {
    const auto t1 = clock::now();
    const TileGrid grid = TileGrid::of(camera.width, camera.height);
    emit_keys(projected_, grid, Pipeline::catgs, options_.list_budget, list_);
    const auto t2 = clock::now();
    sort_render_list(list_, fm::plain_key_packing());
    const auto t3 = clock::now();
    identify_tile_ranges(list_, grid, ranges_);
    plan_slices(ranges_, list_.keys.size(), sp.task_splitting, slices_, static_cast<std::size_t>(sp.min_slice_entries));
    const auto t4 = clock::now();
    cached_.clear();
    for (std::size_t i = 0; i < projected_.tiles_touched.size(); ++i)
      if (projected_.tiles_touched[i] > 0) cached_.push_back(static_cast<uint32_t>(i));
    key_visible_ = cached_.size();
    planner_.start_group(camera, window);
    stats_.preprocess_ms = planning_ms;
    stats_.keys_ms = ms_between(t1, t2);
    stats_.sort_ms = ms_between(t2, t3);
    stats_.ranges_ms = ms_between(t3, t4);
    stats_.render_list_length = list_.keys.size();
    stats_.longest_pass = stats_.render_list_length;
  }
  stats_.key_frame = true;
  stats_.planned_window = planned;
  stats_.window_narrowed = window < planned;
  stats_.predicted_gain = planner_.predicted_gain();
  stats_.measured_gain = planner_.take_measured_gain();
  return window == 0;
}

void SpeculativeRenderer::render_at(const Camera& camera, double time_s, Image& out) {
  validate_camera(camera);
  try {
    draw_at(camera, time_s, out);
  } catch (...) {
    planner_.set_params(options_.speculation);  // the caches may be half made: the next frame is a key frame
    throw;
  }
}

void SpeculativeRenderer::draw_at(const Camera& camera, double time_s, Image& out) {
  const auto start = clock::now();
  stats_ = {};
  const bool candidate = planner_.observe(camera, time_s);
  bool sub = candidate;
  if (candidate) {
    const auto t0 = clock::now();
    sub = update_subframe_features(*model_, chunks_, camera, cached_, projected_,
                                   options_.speculation.subframe_key_colour, key_cut_);
    stats_.preprocess_ms = ms_between(t0, clock::now());
  }
  bool drawn = false;
  if (sub) {
    planner_.subframe_served();
    stats_.key_frame = false;
    stats_.render_list_length = stats_.longest_pass = list_.keys.size();
  } else {
    drawn = key_frame(camera, out);
    stats_.subframe_rejected = candidate;
  }
  if (!drawn) {  // a group's key frame or sub-frame: the key frame's slices
    const auto t5 = clock::now();
    rasterize_slices(projected_, list_, slices_, TileGrid::of(camera.width, camera.height),
                     options_.speculation.early_termination, options_.background, out, &stats_.merge_ms);
    stats_.rasterize_ms = ms_between(t5, clock::now()) - stats_.merge_ms;
    stats_.slices = slices_.size();
  }
  stats_.window = planner_.window();
  stats_.cached = stats_.visible = key_visible_;
  stats_.total_ms = ms_between(start, clock::now());
  if (!stats_.subframe_rejected) {  // a rejected frame's time mixes the attempt and the key frame
    using Kind = SpeculationPlanner::FrameKind;
    planner_.record_cost(!stats_.key_frame    ? Kind::sub
                         : stats_.window == 0 ? Kind::exact
                                              : Kind::key,
                         stats_.window, stats_.total_ms);
  }
}

}  // namespace catgs::cpu
