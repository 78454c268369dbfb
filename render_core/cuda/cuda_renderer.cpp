// CudaRenderer: runs the five stages on its own stream over reusable device buffers.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <string>

#include "depth_grid.h"
#include "forward_model/depth_grid.h"
#include "renderer/render_passes.h"
#include "renderer_state.h"

namespace catgs::cuda {

CudaRenderer::CudaRenderer(std::shared_ptr<const DeviceScene> scene, const RenderOptions& options,
                           const CudaOptions& cuda_options)
    : scene_(std::move(scene)), state_(std::make_unique<State>()), cuda_options_(cuda_options) {
  if (!scene_) throw std::invalid_argument("CudaRenderer: null scene");
  set_options(options);
  const DeviceGuard on(scene_->device());  // the stream, events and buffers live there
  State& s = *state_;
  CATGS_CUDA(cudaStreamCreateWithFlags(&s.stream, cudaStreamNonBlocking));
  for (cudaEvent_t& e : s.events) CATGS_CUDA(cudaEventCreate(&e));
  // The events the host waits on order it only (no timing), and block it where the server asked
  // its lanes to sleep while the GPU works (host_wait_event_flags: else the wait spins).
  const unsigned waited = host_wait_event_flags();
  CATGS_CUDA(cudaEventCreateWithFlags(&s.counts_ready, waited));
  CATGS_CUDA(cudaMallocHost(&s.host_counts, kReadSlots * sizeof(unsigned long long)));
  s.counters.ensure(kCounterSlots * sizeof(unsigned long long), "counters", &s.allocations);
  CATGS_CUDA(cudaEventCreateWithFlags(&s.catgs_readback, waited));
  CATGS_CUDA(cudaEventCreateWithFlags(&s.plan_ready, waited));
  CATGS_CUDA(cudaMallocHost(&s.host_catgs, kHostCatgsSlots * sizeof(unsigned)));
  s.catgs_counters.ensure(kCatgsCounterSlots * sizeof(unsigned), "catgs counters", &s.allocations);
  CATGS_CUDA(cudaEventCreate(&s.convert_start));
  CATGS_CUDA(cudaEventCreate(&s.converted));
  CATGS_CUDA(cudaEventCreateWithFlags(&s.planes_ready, waited));
}

CudaRenderer::~CudaRenderer() {
  try {
    const DeviceGuard on(scene_->device());
    state_.reset();
  } catch (...) {  // destructors must not throw; the buffers are freed on whatever device is current
  }
}

void CudaRenderer::set_options(const RenderOptions& options) {
  state_->planner.set_params(options.speculation);  // validates; closes the open group
  options_ = options;
  state_->occlusion_valid = false;  // a map of other options (a cut, a pipeline) says nothing now
  state_->occlusion_counted = false;
}

void CudaRenderer::set_scene(std::shared_ptr<const DeviceScene> scene) {
  if (!scene) throw std::invalid_argument("CudaRenderer::set_scene: null scene");
  if (scene->device() != scene_->device())
    throw std::invalid_argument("CudaRenderer::set_scene: the scene is on device " + std::to_string(scene->device()) +
                                ", this renderer's buffers on device " + std::to_string(scene_->device()));
  const DeviceGuard on(scene_->device());
  // The previous frame may still read the old scene: finish it before letting go.
  CATGS_CUDA(cudaStreamSynchronize(state_->stream));
  scene_ = std::move(scene);
  state_->planner.set_params(options_.speculation);  // the caches index the old scene
  state_->occlusion_valid = false;
}

CUstream_st* CudaRenderer::stream() const { return state_->stream; }

stages::CameraParams camera_params(const Camera& camera) {
  stages::CameraParams cam{};
  static_cast<fm::View&>(cam) = fm::view_of(camera);
  cam.position = camera.position();
  cam.tiles_x = (camera.width + tune::kTileSize - 1) / tune::kTileSize;
  cam.tiles_y = (camera.height + tune::kTileSize - 1) / tune::kTileSize;
  return cam;
}

void CudaRenderer::State::ensure_frame_buffers(uint64_t n, uint32_t tiles, std::size_t pixels) {
  std::size_t* allocs = &allocations;
  const std::size_t chunks = fm::chunk_count(n);
  scene_chunks = chunks;
  live_chunks.ensure(chunks * sizeof(uint32_t), "kept chunks", allocs);
  live_keep.ensure(chunks * sizeof(uint32_t), "chunk cull answers", allocs);
  live_slot.ensure(chunks * sizeof(uint32_t), "chunk slots", allocs);
  live_scan_temp.ensure(stages::live_scan_temp_bytes(chunks), "chunk slot scan scratch", allocs);
  // The first frame's slots, before any view was counted (fm::initial_slot_chunks); a view that
  // keeps more is pre-processed again once the slots grew (count_render_list's overflow).
  if (slot_chunks == 0) ensure_slots(fm::initial_slot_chunks(chunks), false);
  ranges.ensure(tiles * sizeof(uint2), "tile ranges", allocs);
  heaviest_tile.ensure(sizeof(uint32_t), "heaviest tile", allocs);
  tile_order.ensure(tiles * sizeof(uint32_t), "tile order", allocs);
  rgb.ensure(pixels * 3 * sizeof(float), "RGB image", allocs);
  rgba8.ensure(pixels * sizeof(uint32_t), "RGBA8 image", allocs);
}

void CudaRenderer::State::ensure_slots(uint64_t chunks, bool catgs, bool slack) {
  std::size_t* allocs = &allocations;
  // Slack on the count, not per buffer: every per-slot buffer holds the same slot chunks. The
  // count is recorded only once every buffer holds it (issue 73): a growth that fails part-way
  // leaves slot_chunks at what all of them hold, and the next call grows the rest. No view keeps
  // more chunks than the scene has: the slack stops there. A reservation (`slack` false) takes
  // the count as given: the shape it copies (another session's) holds its slack already, and
  // adding it again made each new session's slots 1.25x the last one's.
  uint64_t want =
      chunks <= slot_chunks
          ? slot_chunks
          : std::max<uint64_t>(chunks, slot_chunks == 0 || !slack
                                           ? chunks
                                           : static_cast<uint64_t>(static_cast<double>(chunks) * tune::kGrowthFactor));
  if (scene_chunks > 0) want = std::min(want, std::max(scene_chunks, slot_chunks));
  if (want > slot_chunks) catgs_sized = false;
  const std::size_t n = want * fm::kChunkSize;
  splat.ensure(n * sizeof(stages::Splat), "splats", allocs, false);
  color.ensure(n * sizeof(float4), "colours", allocs, false);
  depth.ensure(n * sizeof(float), "depths", allocs, false);
  rect.ensure(n * sizeof(ushort4), "tile rectangles", allocs, false);
  tiles_touched.ensure(n * sizeof(uint32_t), "tile counts", allocs, false);
  tile_mask.ensure(n * sizeof(uint32_t), "tile masks", allocs, false);
  ends.ensure((n + 1) * sizeof(uint64_t), "emission offsets", allocs, false);  // + depth_order's spare
  big.ensure(n * sizeof(uint32_t), "big-Gaussian list", allocs, false);
  huge_part_count.ensure(static_cast<std::size_t>(tune::kHugeListed) * tune::kHugeParts * sizeof(uint32_t),
                         "huge-Gaussian part counts", allocs);
  chunk_total.ensure(want * sizeof(uint32_t), "chunk entry counts", allocs, false);
  chunk_start.ensure(want * sizeof(uint64_t), "chunk starts", allocs, false);
  scan_temp.ensure(stages::scan_temp_bytes(want), "scan scratch", allocs);
  slot_chunks = want;
  if (catgs && !catgs_sized) {
    ensure_catgs_buffers();
    catgs_sized = true;
  }
  note_peak();
}

CudaRenderer::State::ListCounts CudaRenderer::State::count_render_list(uint64_t n, const stages::ChunkWalk& walk,
                                                                       const stages::CameraParams& cam,
                                                                       bool depth_first) {
  const stages::Projected proj = projected();
  auto* count = counters.as<unsigned long long>();
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  stages::count_list(proj, n, count + kVisibleCount, count + kReadListLength, stream);
  // The host-device sync of a frame: CUB's radix sort takes the list length from the host, and
  // the list buffers may need to grow before emission writes into them.
  CATGS_CUDA(cudaMemcpyAsync(host_counts, count + kReadListLength, kReadSlots * sizeof(unsigned long long),
                             cudaMemcpyDeviceToHost, stream));
  CATGS_CUDA(cudaEventRecord(counts_ready, stream));
  // Queued behind the readback, so the GPU works while the host waits for it: the chunks' starts
  // and each listed Gaussian's end in the list, where emission in index order needs it (the
  // depth-first order works its own out).
  if (!depth_first) {
    stages::scan_chunks(proj, n, chunk_start.as<uint64_t>(), scan_temp.as<void>(), scan_temp.bytes(), stream);
    stages::gaussian_ends(proj, n, walk, chunk_start.as<uint64_t>(), ends.as<uint64_t>(), stream);
  }
  wait_for(counts_ready);
  ++syncs;
  ListCounts c;
  c.entries = host_counts[0];
  c.visible = host_counts[1];
  c.kept = host_counts[kLiveChunkCount - kReadListLength] & 0xffffffffull;  // its low 32 bits
  c.overflow = c.kept > slot_chunks;
  // The single sort's key (forward_model/key_packing.h): 32-bit [tile | quantised depth] over the
  // listed depths' range, where pre-processing recorded one (preprocess; the speculative
  // pre-processing does not: its lists sort depth first, or with plain keys) and it fits.
  c.packing = fm::single_sort_packing(~static_cast<uint32_t>(host_counts[kReadDepthLowComplement - kReadListLength]),
                                      static_cast<uint32_t>(host_counts[kReadDepthHigh - kReadListLength]), tiles);
  return c;
}

void CudaRenderer::State::emit_render_list(uint64_t n, const stages::ChunkWalk& walk, const stages::CameraParams& cam,
                                           const stages::TileTests& tests, bool depth_first, uint64_t entries,
                                           uint64_t visible, const stages::DepthKeyPacking& packing) {
  const stages::Projected proj = projected();
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  for (int h = 0; h < 2; ++h) {
    keys[h].ensure(entries * sizeof(uint64_t), "render-list keys", &allocations);
    values[h].ensure(entries * sizeof(uint32_t), "render-list values", &allocations);
  }
  uint32_t* v[2] = {values[0].as<uint32_t>(), values[1].as<uint32_t>()};
  if (!depth_first) {
    // Keys of either width live in the 64-bit key buffers.
    const int key_bits = packing.bits + fm::tile_key_bits(tiles);
    const bool narrow = fm::is_narrow(packing);
    sort_temp.ensure(
        narrow ? stages::sort_narrow_temp_bytes(entries, key_bits) : stages::sort_temp_bytes(entries, key_bits),
        "sort scratch", &allocations);
    note_peak();
    uint64_t* k[2] = {keys[0].as<uint64_t>(), keys[1].as<uint64_t>()};
    uint32_t* k32[2] = {keys[0].as<uint32_t>(), keys[1].as<uint32_t>()};
    stages::emit_keys(proj, ends.as<uint64_t>(), n, walk, cam, tests, big_list(), k[0], narrow ? k32[0] : nullptr,
                      packing, v[0], nullptr, 0, stream);
    CATGS_CUDA(cudaEventRecord(events[kKeysEmitted], stream));
    const int half =
        narrow ? stages::sort_pairs_narrow(k32, v, entries, key_bits, sort_temp.as<void>(), sort_temp.bytes(), stream)
               : stages::sort_pairs(k, v, entries, key_bits, sort_temp.as<void>(), sort_temp.bytes(), stream);
    sorted_values = v[half];
    CATGS_CUDA(cudaEventRecord(events[kSorted], stream));
    if (narrow)
      stages::tile_ranges(k32[half], packing, entries, tiles, ranges.as<uint2>(), stream);
    else
      stages::tile_ranges(k[half], packing, entries, tiles, ranges.as<uint2>(), stream);
    return;
  }

  // Depth-first: the visible Gaussians sorted by depth hand out the list slots (the depth sort
  // is timed with emission), then a stable sort on the tile bits alone. The 32-bit tile keys
  // live in the halves of the 64-bit key buffers.
  const int tile_bits = fm::tile_key_bits(tiles);
  for (int h = 0; h < 2; ++h) {  // n: the slots
    depth_index[h].ensure(n * sizeof(uint32_t), "depth order", &allocations);
    depth_keys[h].ensure(n * sizeof(uint32_t), "depth keys", &allocations);
  }
  depth_count.ensure(sizeof(unsigned), "depth order count", &allocations);
  depth_temp.ensure(stages::depth_order_temp_bytes(n), "depth order scratch", &allocations);
  sort_temp.ensure(stages::sort_narrow_temp_bytes(entries, tile_bits), "sort scratch", &allocations);
  note_peak();
  const stages::DepthOrderBuffers order{{depth_index[0].as<uint32_t>(), depth_index[1].as<uint32_t>()},
                                        {depth_keys[0].as<uint32_t>(), depth_keys[1].as<uint32_t>()},
                                        depth_count.as<unsigned>(),
                                        depth_temp.as<void>(),
                                        depth_temp.bytes()};
  const uint32_t* by_depth = stages::depth_order_ends(proj.tiles_touched, proj.chunk_total, proj.depth, n, visible,
                                                      order, ends.as<uint64_t>(), stream);
  uint32_t* k[2] = {keys[0].as<uint32_t>(), keys[1].as<uint32_t>()};
  stages::emit_keys(proj, ends.as<uint64_t>(), n, walk, cam, tests, big_list(), nullptr, k[0], fm::tile_only_packing(),
                    v[0], by_depth, visible, stream);
  CATGS_CUDA(cudaEventRecord(events[kKeysEmitted], stream));
  const int half = stages::sort_pairs_narrow(k, v, entries, tile_bits, sort_temp.as<void>(), sort_temp.bytes(), stream);
  sorted_values = v[half];
  CATGS_CUDA(cudaEventRecord(events[kSorted], stream));
  stages::tile_ranges(k[half], fm::tile_only_packing(), entries, tiles, ranges.as<uint2>(), stream);
}

uint64_t CudaRenderer::State::plan_frame_slices(uint32_t tiles, uint64_t entries, const SpeculationParams& sp,
                                                uint64_t frame_entries, uint32_t first_tile, uint32_t end_tile) {
  const auto min_slice = static_cast<uint64_t>(sp.min_slice_entries);
  // The slice length of the whole frame (a pass splits its tiles as the single pass would).
  const uint64_t avg = stages::split_average(tiles, std::max(entries, frame_entries), min_slice);
  const uint64_t capacity = stages::pass_slice_capacity(tiles, entries, avg);
  const uint64_t slots = entries / avg;
  ensure_slice_buffers(tiles, capacity, slots, occlusion_map_drawn);
  stages::plan_slices(ranges.as<uint2>(), tiles, avg, capacity, sp.task_splitting, slice_plan(),
                      plan_scratch.as<void>(), slice_order.as<uint32_t>(), heaviest_tile.as<uint32_t>(), stream,
                      first_tile, end_tile);
  heaviest = heaviest_tile.as<uint32_t>();  // the longest slice
  return capacity;
}

void CudaRenderer::State::ensure_slice_buffers(uint32_t tiles, uint64_t capacity, uint64_t slots, bool opaque_points) {
  std::size_t* allocs = &allocations;
  slice_range.ensure(capacity * sizeof(uint2), "slice ranges", allocs);
  slice_tile.ensure(capacity * sizeof(uint2), "slice tiles", allocs);
  tile_plan.ensure(tiles * sizeof(uint4), "tile plan", allocs);
  slice_order.ensure(capacity * sizeof(uint32_t), "slice order", allocs);
  plan_scratch.ensure(stages::plan_scratch_bytes(tiles), "slice plan scratch", allocs);
  partials.ensure(std::max<uint64_t>(1, slots) * tune::kRasterThreads * sizeof(float4), "partial slices", allocs);
  if (opaque_points)  // the split slices' own opaque points (rasterize_slices' OpaquePoints)
    occlusion_partial.ensure(std::max<uint64_t>(1, slots) * tune::kRasterThreads * sizeof(uint32_t),
                             "partial opaque points", allocs);
  // The rasterizer's per-tile state starts as task_split.h says, once; its kernels keep it so.
  if (saturated_from.ensure(tiles * sizeof(unsigned), "tile saturation", allocs))
    CATGS_CUDA(cudaMemsetAsync(saturated_from.as<void>(), 0xff, saturated_from.bytes(), stream));
  if (slices_done.ensure(tiles * sizeof(unsigned), "finished slices per tile", allocs))
    CATGS_CUDA(cudaMemsetAsync(slices_done.as<void>(), 0, slices_done.bytes(), stream));
  if (slot_finished.ensure(std::max<uint64_t>(1, slots) * sizeof(unsigned), "finished slices", allocs))
    CATGS_CUDA(cudaMemsetAsync(slot_finished.as<void>(), 0, slot_finished.bytes(), stream));
  note_peak();
}

DeviceFrame CudaRenderer::render_device(const Camera& camera) {
  const DeviceGuard on(scene_->device());
  if (options_.pipeline != Pipeline::catgs) return render_device_at(camera, 0.0);
  return render_device_at(camera, state_->planner.advance_clock());
}

DeviceFrame CudaRenderer::render_device_at(const Camera& camera, double time_s) {
  const DeviceGuard on(scene_->device());
  try {
    if (options_.pipeline == Pipeline::catgs) {
      state_->depth_grid_cell = state_->depth_grid_cols = state_->depth_grid_rows = 0;  // no grid (renderer.h)
      depth_grid_ready_ = false;
      return render_catgs(camera, time_s);
    }
    return render_full(camera);
  } catch (...) {
    drop_inter_frame_state();
    throw;
  }
}

void CudaRenderer::drop_inter_frame_state() {
  State& s = *state_;
  s.planner.set_params(options_.speculation);  // closes the group: the next frame is a key frame
  s.cost_pending = false;
  s.key_frame = true;
  s.occlusion_valid = false;
  s.occlusion_counted = false;
  s.occlusion_map_drawn = false;
  stats_ready_ = true;  // no frame's events to wait for
}

void CudaRenderer::reserve_buffers(int width, int height, const BufferShape& shape) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("CudaRenderer::reserve_buffers: empty viewport");
  const DeviceGuard on(scene_->device());
  State& s = *state_;
  drop_inter_frame_state();  // a buffer that grows loses what it held
  const auto tiles = static_cast<uint32_t>(((width + tune::kTileSize - 1) / tune::kTileSize) *
                                           ((height + tune::kTileSize - 1) / tune::kTileSize));
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  s.ensure_frame_buffers(scene_->size(), tiles, pixels);
  s.ensure_slots((shape.gaussians + fm::kChunkSize - 1) / fm::kChunkSize, options_.pipeline == Pipeline::catgs, false);
  const uint64_t entries = shape.list_entries;
  if (entries > 0) {
    // Exactly the shape, no growth slack: a shape read from another renderer (buffer_shape) holds
    // its slack already, and a second slack would raise the scene's peak with every session.
    for (int h = 0; h < 2; ++h) {
      s.keys[h].ensure(entries * sizeof(uint64_t), "render-list keys", &s.allocations, false);
      s.values[h].ensure(entries * sizeof(uint32_t), "render-list values", &s.allocations, false);
    }
    // The widest key a single sort takes: the tile bits and a 32-bit depth.
    s.sort_temp.ensure(stages::sort_temp_bytes(entries, fm::tile_key_bits(tiles) + 32), "sort scratch", &s.allocations);
  }
  // The split plan at its bound (task_split.h: at most tiles + entries / avg <= 2 tiles slices,
  // entries / avg <= tiles partial slots), and the occlusion maps.
  const bool occlusion = options_.occlusion_culling && options_.pipeline == Pipeline::exact;
  s.ensure_slice_buffers(tiles, 2ull * tiles, tiles, occlusion);
  if (occlusion) {
    for (GrowBuffer& map : s.occlusion_depth) map.ensure(pixels * sizeof(float), "occlusion map", &s.allocations);
    s.occlusion_now.ensure(pixels * sizeof(unsigned), "reprojected occlusion map", &s.allocations);
    s.occlusion_cells.ensure(fm::occlusion_cell_count(width, height) * sizeof(float), "reprojected occlusion cells",
                             &s.allocations);
    s.occlusion_tiles.ensure(tiles * sizeof(float), "occlusion map per tile", &s.allocations);
    s.occlusion_opaque_at.ensure(tiles * sizeof(uint32_t), "opaque points", &s.allocations);
    s.occlusion_behind.ensure(sizeof(unsigned long long), "entries behind opaque points", &s.allocations);
    s.occlusion_behind_host.ensure(sizeof(unsigned long long), "entries behind opaque points (host)");
  }
  const std::size_t planes = pixels + pixels / 2;
  s.yuv.ensure(planes, "YUV planes", &s.allocations);
  s.yuv_host.ensure(planes, "YUV planes (host)");
  s.note_peak();
}

BufferShape CudaRenderer::buffer_shape() const {
  const State& s = *state_;
  return {s.slots(), std::min(s.keys[0].bytes(), s.keys[1].bytes()) / sizeof(uint64_t)};
}

DeviceFrame CudaRenderer::render_full(const Camera& camera) {
  validate_camera(camera);
  State& s = *state_;
  s.syncs = 0;
  CATGS_CUDA(cudaEventRecord(s.events[kStart], s.stream));
  stats_ = {};
  const bool exact = options_.pipeline != Pipeline::vanilla;
  // Occlusion culling (exact): read the last frame's map, write this frame's into the other
  // buffer, filled first with the "never saturated" value for the tiles no slice draws.
  const bool occlusion = exact && options_.occlusion_culling;
  const fm::View view = fm::view_of(camera);
  fm::OcclusionMap map{};
  if (occlusion) {
    const stages::CameraParams cam = camera_params(camera);
    const std::size_t tiles = static_cast<std::size_t>(cam.tiles_x) * cam.tiles_y;
    const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;
    if (s.occlusion_valid) {  // the last map, reprojected onto this frame
      s.occlusion_now.ensure(pixels * sizeof(unsigned), "reprojected occlusion map", &s.allocations);
      s.occlusion_cells.ensure(fm::occlusion_cell_count(camera.width, camera.height) * sizeof(float),
                               "reprojected occlusion cells", &s.allocations);
      map = stages::occlusion_reproject(s.occlusion_depth[s.occlusion_read].as<float>(), s.occlusion_view, view,
                                        s.occlusion_now.as<unsigned>(), s.occlusion_cells.as<float>(), s.stream);
    }
    GrowBuffer& next = s.occlusion_depth[1 - s.occlusion_read];
    next.ensure(pixels * sizeof(float), "occlusion map", &s.allocations);
    s.occlusion_tiles.ensure(tiles * sizeof(float), "occlusion map per tile", &s.allocations);
    s.occlusion_opaque_at.ensure(tiles * sizeof(uint32_t), "opaque points", &s.allocations);
    s.occlusion_behind.ensure(sizeof(unsigned long long), "entries behind opaque points", &s.allocations);
    // The pixels and tiles no slice draws keep these: "never opaque", nothing behind.
    CATGS_CUDA(cudaMemsetAsync(next.as<void>(), 0x7f, pixels * sizeof(float), s.stream));
    CATGS_CUDA(cudaMemsetAsync(s.occlusion_opaque_at.as<void>(), 0xff, tiles * sizeof(uint32_t), s.stream));
    CATGS_CUDA(cudaMemsetAsync(s.occlusion_behind.as<void>(), 0, sizeof(unsigned long long), s.stream));
  }
  s.occlusion_valid = false;  // until this frame has drawn its own
  s.occlusion_map_drawn = occlusion;
  // The depth grid (exact frames): every pass writes its tiles' vertices, so no fill is needed.
  const int cell = exact ? options_.depth_grid_cell : 0;
  s.depth_grid_cell = cell;
  s.depth_grid_cols = cell > 0 ? fm::depth_grid_cols(camera.width, cell) : 0;
  s.depth_grid_rows = cell > 0 ? fm::depth_grid_rows(camera.height, cell) : 0;
  const std::size_t grid_bytes = static_cast<std::size_t>(s.depth_grid_cols) * s.depth_grid_rows * sizeof(float);
  if (cell > 0) s.depth_grid.ensure(grid_bytes, "depth grid", &s.allocations);
  depth_grid_ready_ = false;
  draw_full_frame(camera, exact, true, exact && depth_first_sort(), map, occlusion);
  s.occlusion_map_drawn = false;
  if (occlusion) {  // the entries behind the opaque points, for last_stats (after kMerged: recorded next)
    s.occlusion_behind_host.ensure(sizeof(unsigned long long), "entries behind opaque points (host)");
    CATGS_CUDA(cudaMemcpyAsync(s.occlusion_behind_host.data(), s.occlusion_behind.as<void>(),
                               sizeof(unsigned long long), cudaMemcpyDeviceToHost, s.stream));
  }
  if (cell > 0) {  // for last_depth_grid, as the counter above
    s.depth_grid_host.ensure(grid_bytes, "depth grid (host)");
    CATGS_CUDA(cudaMemcpyAsync(s.depth_grid_host.data(), s.depth_grid.as<void>(), grid_bytes, cudaMemcpyDeviceToHost,
                               s.stream));
  }
  if (occlusion || cell > 0) CATGS_CUDA(cudaEventRecord(s.events[kMerged], s.stream));
  stats_.occlusion_map_used = map.cells[0] != nullptr;
  s.occlusion_counted = occlusion;
  if (occlusion) {
    s.occlusion_read = 1 - s.occlusion_read;
    s.occlusion_view = view;
    s.occlusion_valid = true;
  }
  s.width = camera.width;
  s.height = camera.height;
  stats_ready_ = false;
  return {camera.width, camera.height, s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream};
}

void CudaRenderer::draw_full_frame(const Camera& camera, bool exact, bool early_termination, bool depth_first,
                                   const fm::OcclusionMap& occlusion, bool draw_map) {
  State& s = *state_;
  const DeviceScene& scene = *scene_;
  const uint64_t n = scene.size();
  const stages::CameraParams cam = camera_params(camera);
  const auto tiles = static_cast<uint32_t>(cam.tiles_x * cam.tiles_y);
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;
  s.ensure_frame_buffers(n, tiles, pixels);
  const stages::SceneView sv = scene_view(scene, options_.lod_error_px);
  stages::Projected proj = s.projected();
  auto* counters = s.counters.as<unsigned long long>();
  const RenderListBudget& budget = options_.list_budget;
  const float3 bg = make_float3(options_.background.x, options_.background.y, options_.background.z);
  stages::TileTests tests{
      exact ? stages::TileTestKind::ellipse : stages::TileTestKind::square, proj.splat, {}, cam.width, cam.height};

  // Stage 1 over `region` (every tile, or one pass's), then the counts readback. kPreprocessed
  // marks the whole frame's pre-processing (a frame in passes: the later stage times hold the
  // passes' pre-processing too; total_ms is the frame's). A view that kept more chunks than the
  // slots hold is pre-processed again once they grew (issue 61; records.h Projected).
  auto count = [&](const fm::TileRect& region, bool whole) {
    for (;;) {
      CATGS_CUDA(cudaMemsetAsync(counters, 0, kCounterSlots * sizeof(unsigned long long), s.stream));
      stages::preprocess(sv, cam, exact, region, proj, s.live_chunk_list(), counters + kVisibleCount,
                         counters + kReadDepthLowComplement, s.big_list(), s.stream, occlusion);
      if (whole) CATGS_CUDA(cudaEventRecord(s.events[kPreprocessed], s.stream));
      const State::ListCounts c = s.count_render_list(s.slots(), s.live_walk(), cam, depth_first);
      if (!c.overflow) return c;
      s.ensure_slots(c.kept, false);
      proj = s.projected();
      tests.splat = proj.splat;
    }
  };
  const State::ListCounts frame = count(fm::kAllTiles, true);

  // Stages 2-5 of what was counted last (`c`), over tiles [first, end), sorted with the frame's
  // key and split with the frame's slice length.
  auto draw = [&](const State::ListCounts& c, uint32_t first, uint32_t end) {
    s.emit_render_list(s.slots(), s.live_walk(), cam, tests, depth_first, c.entries, c.visible, frame.packing);
    if (exact) {
      // Load-aware task splitting (paper sec. 3.4), as catgs frames: a tile of over twice the
      // average load is rasterized as slices by several blocks and merged, so a few heavy tiles do
      // not hold the frame's tail (docs/history/render_core_task_split.md, "Exact frames split
      // heavy tiles; a one-block split plan; merges in the rasterizer").
      const uint64_t capacity = s.plan_frame_slices(tiles, c.entries, options_.speculation, frame.entries, first, end);
      CATGS_CUDA(cudaEventRecord(s.events[kRanged], s.stream));
      const stages::SlicePlan plan = s.slice_plan();
      stages::rasterize_slices(
          plan, s.slice_order.as<uint32_t>(), static_cast<uint32_t>(capacity), s.sorted_values, proj, cam,
          early_termination, false, bg, nullptr, s.partials.as<float4>(), s.rgb.as<float>(), s.rgba8.as<uint32_t>(),
          s.stream,
          draw_map ? stages::OpaquePoints{s.occlusion_opaque_at.as<uint32_t>(), s.occlusion_partial.as<uint32_t>(),
                                          s.occlusion_depth[1 - s.occlusion_read].as<float>()}
                   : stages::OpaquePoints{});
      if (s.depth_grid_cell > 0)
        stages::depth_grid(s.ranges.as<uint2>(), s.sorted_values, proj, cam, s.depth_grid_cell, first, end,
                           s.depth_grid.as<float>(), s.stream);
      if (draw_map)
        stages::occlusion_map(s.occlusion_opaque_at.as<uint32_t>(), s.ranges.as<uint2>(), s.sorted_values, proj, first,
                              end, s.occlusion_tiles.as<float>(), s.occlusion_behind.as<unsigned long long>(),
                              s.stream);
    } else {
      // vanilla, the reference 3DGS: a block per tile, the heaviest tiles first
      // (longest-processing-time-first scheduling of the raster blocks).
      stages::order_tiles(s.ranges.as<uint2>() + first, end - first, s.tile_order.as<uint32_t>(),
                          s.heaviest_tile.as<uint32_t>(), s.stream);
      s.heaviest = s.heaviest_tile.as<uint32_t>();
      CATGS_CUDA(cudaEventRecord(s.events[kRanged], s.stream));
      stages::rasterize(s.ranges.as<uint2>(), s.tile_order.as<uint32_t>(), first, end - first, s.sorted_values, proj,
                        cam, bg, s.rgb.as<float>(), s.rgba8.as<uint32_t>(), s.stream);
    }
    CATGS_CUDA(cudaEventRecord(s.events[kRasterized], s.stream));
    CATGS_CUDA(cudaEventRecord(s.events[kMerged], s.stream));  // merged by the slices themselves
  };

  stats_.visible = static_cast<std::size_t>(frame.visible);
  stats_.chunks_preprocessed = static_cast<std::size_t>(frame.kept);
  stats_.render_list_length = static_cast<std::size_t>(frame.entries);
  if (frame.entries <= budget.max_entries(camera.width, camera.height, kBytesPerListEntry)) {
    draw(frame, 0, tiles);
    stats_.passes = 1;
    stats_.longest_pass = stats_.render_list_length;
    return;
  }
  // Over the budget: in passes of tiles (renderer/render_passes.h), the CPU core's driver.
  State::ListCounts pass;
  const PassesDrawn done = draw_in_passes(
      budget, camera.width, camera.height, kBytesPerListEntry, frame.entries, frame.visible,
      [&](const fm::TileRect& region) {
        pass = count(region, false);
        return pass.entries;
      },
      [&](const fm::TileRect& region, uint64_t) {
        draw(pass, first_tile(region, cam.tiles_x), end_tile(region, cam.tiles_x));
      });
  stats_.passes = done.passes;
  stats_.longest_pass = static_cast<std::size_t>(done.longest);
}

const FrameStats& CudaRenderer::last_stats() const {
  if (stats_ready_) return stats_;
  const DeviceGuard on(scene_->device());
  const State& s = *state_;
  CATGS_CUDA(cudaEventSynchronize(s.events[kMerged]));
  auto ms = [&](Event a, Event b) {
    float t = 0.0f;
    CATGS_CUDA(cudaEventElapsedTime(&t, s.events[a], s.events[b]));
    return static_cast<double>(t);
  };
  stats_.preprocess_ms = ms(kStart, kPreprocessed);
  stats_.keys_ms = ms(kPreprocessed, kKeysEmitted);
  stats_.sort_ms = ms(kKeysEmitted, kSorted);
  stats_.ranges_ms = ms(kSorted, kRanged);
  stats_.rasterize_ms = ms(kRanged, kRasterized);
  stats_.total_ms = ms(kStart, kMerged);
  if (s.occlusion_counted)  // copied before kMerged (render_full)
    stats_.entries_behind_opaque =
        static_cast<std::size_t>(*reinterpret_cast<const unsigned long long*>(s.occlusion_behind_host.data()));
  if (options_.pipeline == Pipeline::catgs) {
    if (!s.key_frame) {  // a sub-frame records no key emission, sort or ranges
      stats_.keys_ms = stats_.sort_ms = stats_.ranges_ms = 0.0;
      stats_.rasterize_ms = ms(kPreprocessed, kRasterized);
    }
    wait_for(s.plan_ready);
    stats_.slices = s.host_catgs[kSliceTotals];
  }
  stats_ready_ = true;
  return stats_;
}

const DepthGrid& CudaRenderer::last_depth_grid() const {
  if (depth_grid_ready_) return depth_grid_;
  const State& s = *state_;
  depth_grid_ = DepthGrid{};
  if (s.depth_grid_cols > 0) {
    const DeviceGuard on(scene_->device());
    CATGS_CUDA(cudaEventSynchronize(s.events[kMerged]));  // the copy was queued before it
    depth_grid_.cols = s.depth_grid_cols;
    depth_grid_.rows = s.depth_grid_rows;
    depth_grid_.cell = s.depth_grid_cell;
    const auto* d = reinterpret_cast<const float*>(s.depth_grid_host.data());
    depth_grid_.depth.assign(d, d + static_cast<std::size_t>(s.depth_grid_cols) * s.depth_grid_rows);
  }
  depth_grid_ready_ = true;
  return depth_grid_;
}

std::uint64_t CudaRenderer::device_buffer_bytes() const { return state_->bytes(); }

CudaRenderer::Diagnostics CudaRenderer::diagnostics() const {
  const DeviceGuard on(scene_->device());
  const State& s = *state_;
  Diagnostics d;
  d.buffer_bytes = s.bytes();
  d.peak_buffer_bytes = s.peak_bytes;
  d.allocations = s.allocations;
  d.syncs_last_frame = s.syncs;
  if (s.heaviest && s.width > 0) {
    CATGS_CUDA(cudaEventSynchronize(s.events[kMerged]));
    uint32_t heaviest = 0;
    CATGS_CUDA(cudaMemcpy(&heaviest, s.heaviest, sizeof heaviest, cudaMemcpyDeviceToHost));
    d.heaviest_tile_entries = heaviest;
  }
  d.chunks = fm::chunk_count(scene_->size());
  if (s.width > 0) {
    CATGS_CUDA(cudaEventSynchronize(s.events[kMerged]));
    unsigned kept = 0;
    CATGS_CUDA(cudaMemcpy(&kept, s.live_chunk_list().count, sizeof kept, cudaMemcpyDeviceToHost));
    d.chunks_kept = kept;
  }
  return d;
}

void CudaRenderer::download(const DeviceFrame& f, Image& out) {
  const std::size_t pixels = static_cast<std::size_t>(f.width) * f.height;
  out.width = f.width;
  out.height = f.height;
  out.rgb.resize(pixels * 3);
  out.rgba8.resize(pixels * 4);
  // Packed R | G << 8 | B << 16 | A << 24 is bytes R, G, B, A in memory (little endian).
  CATGS_CUDA(
      cudaMemcpyAsync(out.rgb.data(), f.rgb, pixels * 3 * sizeof(float), cudaMemcpyDeviceToHost, state_->stream));
  CATGS_CUDA(cudaMemcpyAsync(out.rgba8.data(), f.rgba8, pixels * 4, cudaMemcpyDeviceToHost, state_->stream));
  CATGS_CUDA(cudaStreamSynchronize(state_->stream));
}

void CudaRenderer::render(const Camera& camera, Image& out) {
  const DeviceGuard on(scene_->device());
  download(render_device(camera), out);
}

void CudaRenderer::render_at(const Camera& camera, double time_s, Image& out) {
  const DeviceGuard on(scene_->device());
  download(render_device_at(camera, time_s), out);
}

namespace {

// `rows` rows of `width` bytes from `from` (pitch `from_pitch`) to `to` (pitch `to_pitch`).
void copy_plane(const uint8_t* from, int from_pitch, uint8_t* to, int to_pitch, int width, int rows) {
  if (from_pitch == width && to_pitch == width) {
    std::memcpy(to, from, static_cast<std::size_t>(width) * rows);
    return;
  }
  for (int r = 0; r < rows; ++r)
    std::memcpy(to + static_cast<std::size_t>(r) * to_pitch, from + static_cast<std::size_t>(r) * from_pitch,
                static_cast<std::size_t>(width));
}

}  // namespace

double CudaRenderer::render_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) {
  begin_yuv420_at(camera, time_s, out);
  return finish_yuv420();
}

void CudaRenderer::begin_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) {
  check_yuv420_target("render_yuv420_at", out, camera.width, camera.height);
  begin_frame();
  try {
    const DeviceGuard on(scene_->device());
    const DeviceFrame f = render_device_at(camera, time_s);
    State& s = *state_;
    const int w = f.width, h = f.height;
    const std::size_t y_bytes = static_cast<std::size_t>(w) * h, c_bytes = y_bytes / 4;
    stages::Yuv420Pitched planes{};
    if (out.memory == MemoryKind::device) {  // an NVENC hw frame: written in place
      planes = {out.y, static_cast<size_t>(out.y_stride), out.u, static_cast<size_t>(out.u_stride),
                out.v, static_cast<size_t>(out.v_stride)};
    } else {  // converted here, then only the planes cross to the host
      s.yuv.ensure(y_bytes + 2 * c_bytes, "YUV planes", &s.allocations);
      auto* base = s.yuv.as<uint8_t>();
      planes = {base,
                static_cast<size_t>(w),
                base + y_bytes,
                static_cast<size_t>(w / 2),
                base + y_bytes + c_bytes,
                static_cast<size_t>(w / 2)};
    }
    CATGS_CUDA(cudaEventRecord(s.convert_start, s.stream));
    stages::rgba8_to_yuv420(f.rgba8, w, h, planes, s.stream);
    CATGS_CUDA(cudaEventRecord(s.converted, s.stream));
    if (out.memory == MemoryKind::host) {
      // The packed planes in one copy into page-locked memory (a copy into the target's pageable
      // memory goes through the driver's staging, which the lanes' copies share), then, in
      // finish, to the target's strides on the host.
      s.yuv_host.ensure(y_bytes + 2 * c_bytes, "YUV planes (host)");
      CATGS_CUDA(cudaMemcpyAsync(s.yuv_host.data(), s.yuv.as<uint8_t>(), y_bytes + 2 * c_bytes, cudaMemcpyDeviceToHost,
                                 s.stream));
    }
    CATGS_CUDA(cudaEventRecord(s.planes_ready, s.stream));
    begun_target_ = out;
    begun_width_ = w;
    begun_height_ = h;
  } catch (...) {
    drop_inter_frame_state();  // the frame drew, but its planes did not come: as a frame that threw
    end_frame();               // nothing to finish
    throw;
  }
}

bool CudaRenderer::frame_ready() const {
  const DeviceGuard on(scene_->device());
  const cudaError_t e = cudaEventQuery(state_->planes_ready);
  if (e == cudaErrorNotReady) return false;
  CATGS_CUDA(e);  // a real error: finish_yuv420 will meet it too
  return true;
}

double CudaRenderer::finish_yuv420() {
  end_frame();
  const DeviceGuard on(scene_->device());
  State& s = *state_;
  // The encoder reads the planes next, on its own stream or thread: the frame must be complete.
  CATGS_CUDA(cudaStreamSynchronize(s.stream));
  const Yuv420Target& out = begun_target_;
  const int w = begun_width_, h = begun_height_;
  const std::size_t y_bytes = static_cast<std::size_t>(w) * h, c_bytes = y_bytes / 4;
  if (out.memory == MemoryKind::host) {
    const uint8_t* from = s.yuv_host.data();
    copy_plane(from, w, out.y, out.y_stride, w, h);
    copy_plane(from + y_bytes, w / 2, out.u, out.u_stride, w / 2, h / 2);
    copy_plane(from + y_bytes + c_bytes, w / 2, out.v, out.v_stride, w / 2, h / 2);
  }
  float ms = 0.0f;
  CATGS_CUDA(cudaEventElapsedTime(&ms, s.convert_start, s.converted));
  return ms;
}

std::shared_ptr<const DeviceScene> shared_device_scene(const std::shared_ptr<const GaussianModel>& model, int device) {
  if (!model) throw std::invalid_argument("shared_device_scene: null model");
  // The model is held weakly too: a new model at a freed one's address is not taken for it.
  struct Entry {
    std::weak_ptr<const GaussianModel> model;
    std::weak_ptr<const DeviceScene> scene;
  };
  static std::mutex mutex;
  static std::map<std::pair<const GaussianModel*, int>, Entry> uploaded;
  const std::lock_guard<std::mutex> lock(mutex);
  for (auto it = uploaded.begin(); it != uploaded.end();)  // forget what nobody holds
    it = it->second.model.expired() || it->second.scene.expired() ? uploaded.erase(it) : std::next(it);
  const auto found = uploaded.find({model.get(), device});
  if (found != uploaded.end())
    if (auto scene = found->second.scene.lock()) return scene;
  auto scene = DeviceScene::upload(*model, device);
  uploaded[{model.get(), device}] = {model, scene};
  return scene;
}

std::unique_ptr<Renderer> make_cuda_renderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options,
                                             int device) {
  if (!model) throw std::invalid_argument("make_cuda_renderer: null model");
  return std::make_unique<CudaRenderer>(shared_device_scene(model, device), options);
}

}  // namespace catgs::cuda
