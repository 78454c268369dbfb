// The catgs pipeline on the CUDA core (paper sec. 3; docs/DESIGN.md "Speculation"): the host side
// of key frames and sub-frames, mirroring cpu/speculative_renderer.cpp, with SpeculationPlanner
// taking the same decisions from the same poses.
//
// Key frame: M (max_screen_motion, one 4-byte readback) -> W -> speculative pre-processing over
// the predicted path (trails, and each small trail's tile answers as a bit mask) -> the counts
// readback, key emission from those masks (big trails: the trail test), sort (depth first by
// default), tile ranges (count_render_list, emit_render_list) -> frustum cache (select_cached) -> split plan and
// slice order (plan_frame_slices) -> rasterize slices (tile-culled: only entries whose ellipse
// reaches the tile at this pose are blended; the last slice of a split tile merges it). The slice total is copied back
// asynchronously (plan_ready) so the group's sub-frames launch exactly one block per slice; the
// key frame itself launches slice_capacity() blocks, the extra ones return at once. A key frame
// without a window (W = 0: the motion is too fast, the speculation backoff is under way, or the
// caches are off) is an exact frame: the exact pipeline's pre-processing, list, single sort,
// split plan and slices, unculled.
// Sub-frame: features of the cached Gaussians at this pose (and the trail containment flag), the
// check that no unlisted Gaussian reaches the image (the frustum cache's blind spot) ->
// rasterize the key frame's slices (which merge the split tiles) -> read the flag back. A raised flag means some
// on-screen Gaussian left its trail: the frame is rendered again as a key frame. The work is
// queued before the check so the GPU never idles waiting for the host; the rasterizer reads
// the flag itself and return at once when it is raised (on the fast real paths
// most key frames are such failed sub-frames, and drawing them was a large share of their time).
#include <cstring>

#include "renderer_state.h"

namespace catgs::cuda {

DeviceFrame CudaRenderer::render_catgs(const Camera& camera, double time_s) {
  validate_camera(camera);
  State& s = *state_;
  report_cost();
  s.syncs = 0;
  stats_ = {};
  const bool candidate = s.planner.observe(camera, time_s);
  const bool served = candidate && catgs_sub_frame(camera);
  if (served) {
    s.planner.subframe_served();
    stats_.longest_pass = static_cast<std::size_t>(s.key_entries);
  } else {
    catgs_key_frame(camera);  // sets the budget's fields of stats_ (passes, narrowing)
  }
  s.width = camera.width;
  s.height = camera.height;
  stats_.key_frame = s.key_frame;
  stats_.subframe_rejected = candidate && !served;
  stats_.window = s.planner.window();
  stats_.cached = stats_.visible = static_cast<std::size_t>(s.key_visible);
  stats_.render_list_length = static_cast<std::size_t>(s.key_entries);
  stats_ready_ = false;
  s.cost_pending = options_.speculation.cost_model;
  return {camera.width, camera.height, s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream};
}

void CudaRenderer::report_cost() {
  State& s = *state_;
  if (!s.cost_pending) return;
  s.cost_pending = false;
  // cudaErrorNotReady is no error: the frame is still running, and this sample is skipped.
  if (cudaEventQuery(s.events[kMerged]) != cudaSuccess) return;
  const FrameStats& st = last_stats();
  if (st.subframe_rejected) return;  // its time is the key frame's alone (kStart was recorded again)
  using Kind = SpeculationPlanner::FrameKind;
  s.planner.record_cost(!st.key_frame ? Kind::sub : st.window == 0 ? Kind::exact : Kind::key, st.window, st.total_ms);
}

void CudaRenderer::State::ensure_catgs_buffers() {
  std::size_t* allocs = &allocations;
  const uint64_t n = slots();
  trail_mean0_motion.ensure(n * sizeof(float4), "trail means", allocs);
  trail_conic_q.ensure(n * sizeof(float4), "trail conics", allocs);
  trail_cov.ensure(n * sizeof(float4), "trail covariances", allocs);
  trail_mask.ensure(n * sizeof(uint32_t), "trail tile masks", allocs);
  cached.ensure(n * sizeof(uint32_t), "frustum cache", allocs);
  select_temp.ensure(stages::select_cached_temp_bytes(n), "frustum cache scratch", allocs);
}

int CudaRenderer::State::measure_window(const stages::SceneView& scene, const stages::CameraParams& key,
                                        const stages::CameraParams& next, float depth_threshold) {
  unsigned* cc = catgs_counters.as<unsigned>();
  CATGS_CUDA(cudaMemsetAsync(cc + kMotionBits, 0, sizeof(unsigned), stream));
  stages::max_screen_motion(scene, key, next, depth_threshold, cc + kMotionBits, stream);
  CATGS_CUDA(
      cudaMemcpyAsync(host_catgs + kMotionBits, cc + kMotionBits, sizeof(unsigned), cudaMemcpyDeviceToHost, stream));
  CATGS_CUDA(cudaEventRecord(catgs_readback, stream));
  wait_for(catgs_readback);
  ++syncs;
  float motion = 0.0f;
  std::memcpy(&motion, host_catgs + kMotionBits, sizeof motion);
  return planner.window_for(motion);
}

void CudaRenderer::catgs_key_frame(const Camera& camera) {
  State& s = *state_;
  const SpeculationParams& sp = options_.speculation;
  const uint64_t n = scene_->size();
  const stages::CameraParams cam = camera_params(camera);
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  s.ensure_frame_buffers(n, tiles, static_cast<std::size_t>(camera.width) * camera.height);
  s.ensure_slots(0, true);  // the trails and frustum cache follow the slots
  const stages::SceneView sv = scene_view(*scene_, options_.lod_error_px);

  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  // The window from the predicted path (never from future input): M over one frame, then W.
  const int planned = s.planner.window_wanted()
                          ? s.measure_window(sv, cam, camera_params(s.planner.next_camera(camera)), sp.depth_threshold)
                          : 0;
  auto* counters = s.counters.as<unsigned long long>();
  const RenderListBudget& budget = options_.list_budget;
  const uint64_t limit = budget.max_entries(camera.width, camera.height, kBytesPerListEntry);
  // A window whose trail list is over the budget is narrowed (issue 35), as the CPU core does
  // from the same counts (SpeculationPlanner::narrower_window); giant Gaussians are refused at once.
  int window = planned;
  State::ListCounts counts;
  for (; window > 0; window = SpeculationPlanner::narrower_window(window)) {
    const std::vector<Camera> path = s.planner.path(camera, window);
    stages::PathParams pp{};
    pp.count = static_cast<int>(path.size());
    for (std::size_t k = 0; k < path.size(); ++k) pp.cam[k] = camera_params(path[k]);
    // A view that keeps more chunks than the slots hold is pre-processed again once they grew
    // (issue 61; records.h Projected).
    do {
      if (counts.overflow) s.ensure_slots(counts.kept, true);
      CATGS_CUDA(cudaMemsetAsync(counters, 0, kCounterSlots * sizeof(unsigned long long), s.stream));
      stages::speculative_preprocess(sv, pp, trail_widening(sp, window), s.projected(), s.trails(), s.live_chunk_list(),
                                     counters + kVisibleCount, s.big_list(), s.stream);
      counts = s.count_render_list(s.slots(), s.live_walk(), cam, depth_first_sort());
    } while (counts.overflow);
    if (counts.entries <= limit) break;
    budget.check_reach(counts.entries, counts.visible, camera.width, camera.height, kBytesPerListEntry);
  }
  stats_.planned_window = planned;
  stats_.window_narrowed = window < planned;
  unsigned* cc = s.catgs_counters.as<unsigned>();

  if (window == 0) {
    // No window: the frame is rendered in full by the exact pipeline's stages (a one-pose trail
    // is the exact ellipse, so the list is the same; the path-wide kernel only costs more), in
    // passes over the budget, and opens no group. Task splitting still applies.
    draw_full_frame(camera, true, sp.early_termination, false);
    CATGS_CUDA(cudaMemcpyAsync(s.host_catgs + kSliceTotals, cc + kSliceTotals, 2 * sizeof(unsigned),
                               cudaMemcpyDeviceToHost, s.stream));
    CATGS_CUDA(cudaEventRecord(s.plan_ready, s.stream));
    s.key_entries = stats_.render_list_length;
    s.key_visible = stats_.visible;
    s.key_capacity = 0;  // no group: no sub-frame rasterizes this plan
  } else {
    CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));
    // The depth-first sort pays for a trail list, several times the exact one; an exact list sorts
    // faster in one radix sort, as the exact pipeline does (docs/history/
    // render_core_sort_and_keys.md, "The depth-first sort").
    const stages::Projected proj = s.projected();
    const stages::TileTests tests{stages::TileTestKind::trail, nullptr, s.trails(), cam.width, cam.height};
    s.emit_render_list(s.slots(), s.live_walk(), cam, tests, depth_first_sort(), counts.entries, counts.visible,
                       counts.packing);
    // the frustum cache, for the group's sub-frames
    stages::select_cached(proj.tiles_touched, proj.chunk_total, s.slots(), s.cached.as<uint32_t>(), cc + kCachedCount,
                          s.select_temp.as<void>(), s.select_temp.bytes(), s.stream);
    const uint64_t capacity = s.plan_frame_slices(tiles, counts.entries, sp);  // paper sec. 3.4
    // The group's sub-frames launch one block per slice: the totals come back while this frame
    // rasterizes, and only a sub-frame waits for them (plan_ready).
    CATGS_CUDA(cudaMemcpyAsync(s.host_catgs + kSliceTotals, cc + kSliceTotals, 2 * sizeof(unsigned),
                               cudaMemcpyDeviceToHost, s.stream));
    CATGS_CUDA(cudaEventRecord(s.plan_ready, s.stream));
    CATGS_CUDA(cudaEventRecord(s.events[kRanged], s.stream));
    catgs_rasterize(camera, static_cast<uint32_t>(capacity), nullptr, true);
    s.key_entries = counts.entries;
    s.key_visible = counts.visible;
    s.key_capacity = capacity;
    stats_.passes = 1;
    stats_.longest_pass = static_cast<std::size_t>(counts.entries);
  }
  s.key_frame = true;
  s.planner.start_group(camera, window);
  stats_.predicted_gain = s.planner.predicted_gain();
  stats_.measured_gain = s.planner.take_measured_gain();
}

bool CudaRenderer::catgs_sub_frame(const Camera& camera) {
  State& s = *state_;
  unsigned* cc = s.catgs_counters.as<unsigned>();
  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  CATGS_CUDA(cudaMemsetAsync(cc + kOutside, 0, sizeof(unsigned), s.stream));
  stages::update_subframe_features(scene_view(*scene_, options_.lod_error_px), camera_params(camera),
                                   s.cached.as<uint32_t>(), static_cast<uint32_t>(s.key_visible),
                                   s.live_chunks.as<uint32_t>(), options_.speculation.subframe_key_colour,
                                   s.projected(), s.trails(), cc + kOutside, s.stream);
  // The group's LOD cut is its key frame's (the key camera's): a chunk outside it is drawn by
  // another level, so its unlisted Gaussians must not turn the frame into a key frame.
  stages::check_unlisted(scene_view(*scene_, options_.lod_error_px), camera_params(camera),
                         camera_params(s.planner.key_camera()), s.tiles_touched.as<uint32_t>(),
                         s.chunk_total.as<uint32_t>(), s.live_chunk_list(), cc + kOutside, s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));
  CATGS_CUDA(cudaEventSynchronize(s.plan_ready));  // the key frame's slice total, long since copied
  // Nothing is drawn if the check failed.
  catgs_rasterize(camera, s.host_catgs[kSliceTotals], cc + kOutside, true);
  CATGS_CUDA(
      cudaMemcpyAsync(s.host_catgs + kOutside, cc + kOutside, sizeof(unsigned), cudaMemcpyDeviceToHost, s.stream));
  CATGS_CUDA(cudaEventRecord(s.catgs_readback, s.stream));
  wait_for(s.catgs_readback);
  ++s.syncs;
  s.key_frame = false;
  return s.host_catgs[kOutside] == 0u;
}

void CudaRenderer::catgs_rasterize(const Camera& camera, uint32_t blocks, const unsigned* abandon, bool trail_list) {
  State& s = *state_;
  const stages::CameraParams cam = camera_params(camera);
  const float3 bg = make_float3(options_.background.x, options_.background.y, options_.background.z);
  const stages::SlicePlan plan = s.slice_plan();
  stages::rasterize_slices(plan, s.slice_order.as<uint32_t>(), blocks, s.sorted_values, s.projected(), cam,
                           options_.speculation.early_termination, cuda_options_.tile_culling && trail_list, bg,
                           abandon, s.partials.as<float4>(), s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kRasterized], s.stream));
  CATGS_CUDA(cudaEventRecord(s.events[kMerged], s.stream));  // merged by the slices themselves
}

}  // namespace catgs::cuda
