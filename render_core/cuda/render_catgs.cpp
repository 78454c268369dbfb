// The catgs pipeline on the CUDA core (paper sec. 3; DESIGN.md 1-3): the host side of key frames
// and sub-frames, mirroring cpu/speculative_renderer.cpp, with SpeculationPlanner taking the
// same decisions from the same poses.
//
// Key frame: M (max_screen_motion, one 4-byte readback) -> W -> speculative pre-processing over
// the predicted path (trails, and each small trail's tile answers as a bit mask) -> the counts
// readback, key emission from those masks (big trails: the trail test), sort (depth first by
// default), tile ranges (build_render_list) -> frustum cache (select_cached) -> split plan and slice order (k first,
// then longest first) -> rasterize slices (tile-culled: only entries whose ellipse reaches the
// tile at this pose are blended) -> merge. The slice total is copied back asynchronously (plan_ready) so the
// group's sub-frames launch exactly one block per slice; the key frame itself launches
// slice_capacity() blocks, the extra ones return at once. A key frame without a window (W = 0:
// the motion is too fast, the speculation
// backoff is under way, or the caches are off) runs the exact pipeline's pre-processing, list
// and single sort instead, then the same split plan and slices, unculled.
// Sub-frame: features of the cached Gaussians at this pose (and the trail containment flag), the
// check that no unlisted Gaussian reaches the image (the frustum cache's blind spot) ->
// rasterize the key frame's slices -> merge -> read the flag back. A raised flag means some
// on-screen Gaussian left its trail: the frame is rendered again as a key frame. The work is
// queued before the check so the GPU never idles waiting for the host; the raster and merge
// kernels read the flag themselves and return at once when it is raised (on the fast real paths
// most key frames are such failed sub-frames, and drawing them cost ~1.5 ms on the city).
#include <cstring>

#include "renderer_state.h"

namespace catgs::cuda {

namespace {

// catgs_counters slots.
constexpr int kMotionBits = 0, kOutside = 1, kSliceTotals = 2, kCachedCount = 4;

}  // namespace

DeviceFrame CudaRenderer::render_catgs(const Camera& camera, double time_s) {
  validate_camera(camera);
  State& s = *state_;
  s.syncs = 0;
  const bool candidate = s.planner.observe(camera, time_s);
  const bool served = candidate && catgs_sub_frame(camera);
  if (served)
    s.planner.subframe_served();
  else
    catgs_key_frame(camera);
  s.width = camera.width;
  s.height = camera.height;
  stats_ = {};
  stats_.key_frame = s.key_frame;
  stats_.subframe_rejected = candidate && !served;
  stats_.window = s.planner.window();
  stats_.cached = stats_.visible = static_cast<std::size_t>(s.key_visible);
  stats_.render_list_length = static_cast<std::size_t>(s.key_entries);
  stats_ready_ = false;
  return {camera.width, camera.height, s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream};
}

void CudaRenderer::catgs_key_frame(const Camera& camera) {
  State& s = *state_;
  const DeviceScene& scene = *scene_;
  const SpeculationParams& sp = options_.speculation;
  const uint64_t n = scene.size();
  std::size_t* allocs = &s.allocations;
  const stages::CameraParams cam = camera_params(camera);
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  s.ensure_frame_buffers(n, tiles, static_cast<std::size_t>(camera.width) * camera.height);
  s.trail_mean0_motion.ensure(n * sizeof(float4), "trail means", allocs);
  s.trail_conic_q.ensure(n * sizeof(float4), "trail conics", allocs);
  s.trail_cov.ensure(n * sizeof(float4), "trail covariances", allocs);
  s.trail_mask.ensure(n * sizeof(uint32_t), "trail tile masks", allocs);
  s.cached.ensure(n * sizeof(uint32_t), "frustum cache", allocs);
  s.select_temp.ensure(stages::select_cached_temp_bytes(n), "frustum cache scratch", allocs);
  const stages::SceneView sv = scene_view(scene);
  unsigned* cc = s.catgs_counters.as<unsigned>();
  auto* counters = s.counters.as<unsigned long long>();

  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  // The window from the predicted path (never from future input): M over one frame, then W.
  int window = 0;
  if (s.planner.window_wanted()) {
    CATGS_CUDA(cudaMemsetAsync(cc + kMotionBits, 0, sizeof(unsigned), s.stream));
    stages::max_screen_motion(sv, cam, camera_params(s.planner.next_camera(camera)), sp.depth_threshold,
                              cc + kMotionBits, s.stream);
    CATGS_CUDA(cudaMemcpyAsync(s.host_catgs + kMotionBits, cc + kMotionBits, sizeof(unsigned),
                               cudaMemcpyDeviceToHost, s.stream));
    CATGS_CUDA(cudaEventRecord(s.catgs_readback, s.stream));
    CATGS_CUDA(cudaEventSynchronize(s.catgs_readback));
    ++s.syncs;
    float motion = 0.0f;
    std::memcpy(&motion, s.host_catgs + kMotionBits, sizeof motion);
    window = s.planner.window_for(motion);
  }
  const stages::Projected proj = s.projected();
  CATGS_CUDA(cudaMemsetAsync(counters, 0, 4 * sizeof(unsigned long long), s.stream));
  stages::TileTests tests{stages::TileTestKind::trail, nullptr, s.trails(), cam.width, cam.height};
  if (window > 0) {
    const std::vector<Camera> path = s.planner.path(camera, window);
    stages::PathParams pp{};
    pp.count = static_cast<int>(path.size());
    for (std::size_t k = 0; k < path.size(); ++k) pp.cam[k] = camera_params(path[k]);
    stages::speculative_preprocess(sv, pp, trail_widening(sp, window), proj, s.trails(), counters, s.big_list(),
                                   s.stream);
  } else {
    // No window: the frame is rendered in full by the exact pipeline's stages (a one-pose trail
    // is the exact ellipse, so the list is the same; the path-wide kernel only costs more) and
    // opens no group. Task splitting still applies.
    stages::preprocess(sv, cam, true, proj, counters, s.big_list(), s.stream);
    tests = {stages::TileTestKind::ellipse, proj.splat, {}, cam.width, cam.height};
  }
  CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));

  // The depth-first sort pays for a trail list (1.7-3.4x the exact one on the city's real paths);
  // an exact list sorts faster in one radix sort, as the exact pipeline does (H100, city bicycle:
  // key emission + sort 1.20 ms depth first against 1.09 ms for exact's single sort).
  uint64_t visible = 0;
  const uint64_t entries = s.build_render_list(n, cam, tests, window > 0 && depth_first_sort(), &visible);

  // Frustum cache (for the group's sub-frames), split plan (paper sec. 3.4) and the slice order
  // (longest first).
  if (window > 0)
    stages::select_cached(proj.tiles_touched, n, s.cached.as<uint32_t>(), cc + kCachedCount,
                          s.select_temp.as<void>(), s.select_temp.bytes(), s.stream);
  const auto min_slice = static_cast<uint64_t>(sp.min_slice_entries);
  const uint64_t capacity = stages::slice_capacity(tiles, entries, min_slice);
  const uint64_t slots = entries / stages::split_average(tiles, entries, min_slice);
  s.slice_range.ensure(capacity * sizeof(uint2), "slice ranges", allocs);
  s.slice_tile.ensure(capacity * sizeof(uint2), "slice tiles", allocs);
  s.tile_plan.ensure(tiles * sizeof(uint4), "tile plan", allocs);
  s.plan_scan.ensure(2 * static_cast<std::size_t>(tiles) * sizeof(uint64_t), "split scan", allocs);
  s.plan_temp.ensure(stages::plan_slices_temp_bytes(tiles), "split scan scratch", allocs);
  s.slice_scratch.ensure(3 * capacity * sizeof(uint32_t), "slice loads", allocs);
  s.slice_order.ensure(capacity * sizeof(uint32_t), "slice order", allocs);
  s.slice_order_temp.ensure(stages::order_slices_temp_bytes(capacity), "slice order scratch", allocs);
  s.saturated_from.ensure(tiles * sizeof(unsigned), "tile saturation", allocs);
  s.partials.ensure(std::max<uint64_t>(1, slots) * tune::kRasterThreads * sizeof(float4), "partial slices", allocs);
  s.slot_finished.ensure(std::max<uint64_t>(1, slots) * sizeof(unsigned), "finished slices", allocs);
  s.note_peak();
  const stages::SlicePlan plan = s.slice_plan();
  stages::plan_slices(s.ranges.as<uint2>(), tiles, entries, sp.task_splitting, min_slice, plan, s.plan_scan.as<uint64_t>(),
                      s.plan_temp.as<void>(), s.plan_temp.bytes(), s.stream);
  stages::order_slices(plan, capacity, s.slice_scratch.as<uint32_t>(), s.slice_order.as<uint32_t>(),
                       s.slice_order_temp.as<void>(), s.slice_order_temp.bytes(), s.stream);
  // The first sorted key is the longest first slice, the longest slice of all (task_split.cu).
  s.heaviest = s.slice_scratch.as<uint32_t>() + 2 * capacity;
  s.heaviest_is_slice_key = true;
  CATGS_CUDA(cudaMemcpyAsync(s.host_catgs + kSliceTotals, cc + kSliceTotals, 2 * sizeof(unsigned),
                             cudaMemcpyDeviceToHost, s.stream));
  CATGS_CUDA(cudaEventRecord(s.plan_ready, s.stream));
  CATGS_CUDA(cudaEventRecord(s.events[kRanged], s.stream));

  catgs_rasterize(camera, static_cast<uint32_t>(capacity), nullptr, window > 0);
  s.key_entries = entries;
  s.key_visible = visible;
  s.key_capacity = capacity;
  s.key_frame = true;
  s.planner.start_group(camera, window);
}

bool CudaRenderer::catgs_sub_frame(const Camera& camera) {
  State& s = *state_;
  unsigned* cc = s.catgs_counters.as<unsigned>();
  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  CATGS_CUDA(cudaMemsetAsync(cc + kOutside, 0, sizeof(unsigned), s.stream));
  stages::update_subframe_features(scene_view(*scene_), camera_params(camera), s.cached.as<uint32_t>(),
                                   static_cast<uint32_t>(s.key_visible), s.projected(), s.trails(), cc + kOutside,
                                   s.stream);
  stages::check_unlisted(scene_view(*scene_), camera_params(camera), s.tiles_touched.as<uint32_t>(), cc + kOutside,
                         s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));
  CATGS_CUDA(cudaEventSynchronize(s.plan_ready));  // the key frame's slice total, long since copied
  // Nothing is drawn if the check failed.
  catgs_rasterize(camera, s.host_catgs[kSliceTotals], cc + kOutside, true);
  CATGS_CUDA(cudaMemcpyAsync(s.host_catgs + kOutside, cc + kOutside, sizeof(unsigned), cudaMemcpyDeviceToHost,
                             s.stream));
  CATGS_CUDA(cudaEventRecord(s.catgs_readback, s.stream));
  CATGS_CUDA(cudaEventSynchronize(s.catgs_readback));
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
                           options_.speculation.early_termination, cuda_options_.tile_culling && trail_list, bg, abandon, s.partials.as<float4>(), s.rgb.as<float>(),
                           s.rgba8.as<uint32_t>(), s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kRasterized], s.stream));
  stages::merge_slices(plan, s.partials.as<float4>(), cam, options_.speculation.early_termination, bg, abandon, s.rgb.as<float>(), s.rgba8.as<uint32_t>(),
                       s.stream);
  CATGS_CUDA(cudaEventRecord(s.events[kMerged], s.stream));
}

}  // namespace catgs::cuda
