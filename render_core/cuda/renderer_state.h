// Internal to the CUDA core: the state a CudaRenderer owns (stream, events, reusable device
// buffers), shared by cuda_renderer.cpp (vanilla, exact) and render_catgs.cpp (catgs).
#pragma once

#include <algorithm>
#include <chrono>
#include <string>

#include "speculation/speculation_planner.h"
#include "base/allocation_faults.h"
#include "base/cuda_check.h"
#include "cuda/cuda_renderer.h"
#include "stages.h"
#include "tunables.h"

namespace catgs::cuda {

// A device allocation that only grows (by tune::kGrowthFactor), never per frame.
class GrowBuffer {
 public:
  GrowBuffer() = default;
  GrowBuffer(const GrowBuffer&) = delete;
  GrowBuffer& operator=(const GrowBuffer&) = delete;
  ~GrowBuffer() {
    if (ptr_) cudaFree(ptr_);
  }

  // Makes room for `bytes`; returns true when it had to reallocate (contents are then lost).
  // cudaFree waits for in-flight work on the device, so a buffer still read by an earlier frame
  // is never freed under it. Throws OutOfMemoryError naming the buffer and its size when device
  // memory runs out (or the allocation-fault hook says so, base/allocation_faults.h); the buffer
  // then holds nothing and bytes() says 0, so a later ensure allocates it again.
  // `slack`: take tune::kGrowthFactor times the need (false: the caller sized it with its own).
  bool ensure(std::size_t bytes, const char* what, std::size_t* allocations, bool slack = true) {
    if (bytes <= bytes_) return false;
    const auto want = slack ? static_cast<std::size_t>(static_cast<double>(bytes) * tune::kGrowthFactor) + 256 : bytes;
    if (ptr_) CATGS_CUDA(cudaFree(ptr_));
    ptr_ = nullptr;
    bytes_ = 0;
    if (allocation_fault(want, what)) throw_out_of_memory("CUDA renderer", what, bytes, "allocation fault injected");
    std::size_t got = want;
    if (cudaMalloc(&ptr_, want) != cudaSuccess) {
      // No room for the slack: take exactly what this frame needs (huge lists near the limit).
      (void)cudaGetLastError();
      ptr_ = nullptr;
      got = bytes;
      const cudaError_t e = cudaMalloc(&ptr_, bytes);
      if (e != cudaSuccess) {
        (void)cudaGetLastError();
        ptr_ = nullptr;
        throw_out_of_memory("CUDA renderer", what, bytes,
                            std::string("cudaMalloc failed: ") + cudaGetErrorName(e) + ": " + cudaGetErrorString(e));
      }
    }
    bytes_ = got;
    ++*allocations;
    return true;
  }
  template <typename T>
  T* as() const {
    return static_cast<T*>(ptr_);
  }
  std::size_t bytes() const { return bytes_; }

 private:
  void* ptr_ = nullptr;
  std::size_t bytes_ = 0;
};

// Page-locked host memory that only grows: where a frame's I420 planes land from the device, so
// the copy is a DMA at the link's rate rather than through the driver's pageable staging.
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  ~PinnedBuffer() {
    if (ptr_) cudaFreeHost(ptr_);
  }
  // Room for `bytes` (contents lost when it grows); throws OutOfMemoryError when the host refuses
  // (or the allocation-fault hook says so), holding nothing then.
  void ensure(std::size_t bytes, const char* what) {
    if (bytes <= bytes_) return;
    if (ptr_) CATGS_CUDA(cudaFreeHost(ptr_));
    ptr_ = nullptr;
    bytes_ = 0;
    if (allocation_fault(bytes, what)) throw_out_of_memory("CUDA renderer", what, bytes, "allocation fault injected");
    const cudaError_t e = cudaMallocHost(&ptr_, bytes);
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      ptr_ = nullptr;
      throw_out_of_memory("CUDA renderer", what, bytes,
                          std::string("cudaMallocHost failed: ") + cudaGetErrorName(e) + ": " + cudaGetErrorString(e));
    }
    bytes_ = bytes;
  }
  std::uint8_t* data() const { return static_cast<std::uint8_t*>(ptr_); }

 private:
  void* ptr_ = nullptr;
  std::size_t bytes_ = 0;
};

// Slots of State::counters (64-bit, device): the running visible count, the frame's 48-byte
// readback (render-list length, visible count, the listed Gaussians' depth range as float bits,
// the low end complemented so that both ends are running maxima from zero, the big-Gaussian
// count, and the chunks pre-processing kept: the one copy count_render_list syncs on), the
// big-Gaussian count (stages::BigList::count, its low 32 bits; its high 32 bits: the huge ones')
// and the chunks pre-processing kept (stages::LiveChunks, low 32 bits).
enum CounterSlot {
  kVisibleCount = 0,
  kReadListLength = 1,
  kReadVisible = 2,
  kReadDepthLowComplement = 3,
  kReadDepthHigh = 4,
  kBigCount = 5,
  kLiveChunkCount = 6,
  kReadSlots = 6,  // slots 1..6
  kCounterSlots = 7
};
// Slots of State::catgs_counters (32-bit, device) and of its pinned host mirror host_catgs (the
// first kHostCatgsSlots): M's float bits, the sub-frame's "outside its trail" flag, the key
// frame's slice and partial-slot totals (stages::SlicePlan::totals) and the frustum-cache size.
enum CatgsCounterSlot {
  kMotionBits = 0,
  kOutside = 1,
  kSliceTotals = 2,  // and 3: partial slots
  kCachedCount = 4,
  kHostCatgsSlots = 4,
  kCatgsCounterSlots = 8
};

// Frame events: a key frame records all; a catgs sub-frame records kStart, kPreprocessed (its
// features), kRasterized and kMerged. vanilla/exact: kMerged = kRasterized.
enum Event { kStart, kPreprocessed, kKeysEmitted, kSorted, kRanged, kRasterized, kMerged, kEventCount };

// The camera as the kernels see it.
stages::CameraParams camera_params(const Camera& camera);

// How long a host wait for a frame's readback polls before it sleeps (wait_for), microseconds.
inline constexpr int kPollBeforeSleepUs = 150;

// Waits for `event`, recorded on the renderer's stream. Under HostWait::block it first polls the
// event for up to kPollBeforeSleepUs, then sleeps in cudaEventSynchronize (the event was made
// with host_wait_event_flags): a readback the GPU answers at once costs no sleep's wake-up, one
// queued behind other lanes' work costs the poll, not its whole wait on a core (issue 92;
// RESULTS.md, "The server's cores by thread"). HostWait::spin: spins.
inline void wait_for(cudaEvent_t event) {
  if (host_wait() == HostWait::block) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(kPollBeforeSleepUs);
    for (;;) {
      const cudaError_t e = cudaEventQuery(event);
      if (e == cudaSuccess) return;
      if (e != cudaErrorNotReady || std::chrono::steady_clock::now() >= until) break;
    }
  }
  CATGS_CUDA(cudaEventSynchronize(event));
}

// The scene as the kernels see it.
// The scene as the kernels read it, its LOD cut at bound `lod_error_px` (RenderOptions).
inline stages::SceneView scene_view(const DeviceScene& scene, float lod_error_px) {
  return {scene.means(),
          scene.log_scales(),
          scene.rotations(),
          scene.opacity_logits(),
          reinterpret_cast<const __half*>(scene.sh()),
          scene.sh_degree(),
          scene.size(),
          scene.chunks(),
          scene.lod(),
          lod_error_px,
          scene.rotation_codes(),
          scene.scale_codes(),
          reinterpret_cast<const uchar4*>(scene.colour_codes()),
          scene.sh_codes(),
          scene.sh_code_bytes(),
          scene.chunk_ranges(),
          scene.opacity_lut()};
}

struct CudaRenderer::State {
  cudaStream_t stream = nullptr;
  cudaEvent_t events[kEventCount] = {};
  cudaEvent_t counts_ready = nullptr;
  unsigned long long* host_counts = nullptr;  // pinned [kReadSlots]: from kReadListLength on
  std::size_t allocations = 0, peak_bytes = 0;
  int syncs = 0;
  int width = 0, height = 0;

  // Per slot (records.h Projected: the Gaussians of the chunks a frame keeps, issue 61), for
  // slot_chunks slot chunks; they grow only when a view keeps more chunks than any before.
  GrowBuffer splat, color, depth, rect, tiles_touched, tile_mask, ends, scan_temp, big, huge_part_count;
  // Per slot chunk: render-list entries and where the slot chunk's start.
  GrowBuffer chunk_total, chunk_start;
  // Per scene chunk (4 bytes each: 1/64 of a Gaussian's bytes per chunk): the kept chunks
  // (stages::LiveChunks: the list, the cull's answers, their slot chunks) and the ordering
  // scan's scratch.
  GrowBuffer live_chunks, live_keep, live_slot, live_scan_temp;
  uint64_t slot_chunks = 0;   // the slot chunks the per-slot buffers hold
  uint64_t scene_chunks = 0;  // the scene's chunks (ensure_frame_buffers): the most a view keeps
  // Per render-list entry (two halves each, for the radix sort's double buffer).
  GrowBuffer keys[2], values[2], sort_temp;
  // The depth-first sort (depth_order.cu): visible Gaussians and their depth keys (two halves
  // each), its count and scratch.
  GrowBuffer depth_index[2], depth_keys[2], depth_count, depth_temp;
  // Per tile / pixel, and the small counters.
  GrowBuffer ranges, heaviest_tile, tile_order, rgb, rgba8, counters;
  const uint32_t* sorted_values = nullptr;
  const uint32_t* heaviest = nullptr;  // device: entries of the heaviest tile (or slice)

  // The split plan of exact frames and catgs key frames (per slice and tile: plan_frame_slices),
  // and the partial slices of split tiles.
  GrowBuffer slice_range, slice_tile, tile_plan, slice_order, partials, saturated_from, slices_done, slot_finished;
  GrowBuffer plan_scratch;  // task_split.cu: the counting pass's per-block results
  // Occlusion culling (RenderOptions::occlusion_culling; forward_model/occlusion.h): the last
  // exact frame's per-pixel map (occlusion_depth[occlusion_read], drawn at occlusion_view; valid once a
  // frame with the current options and scene drew it) and the other buffer, which the next frame
  // writes while its pre-processing reads this one (two: a frame drawn in passes reads the old
  // map after its first pass wrote the new one).
  // occlusion_opaque_at: this frame's opaque point per tile (rasterize_slices), occlusion_behind:
  // its entries behind them (FrameStats::entries_behind_opaque).
  // occlusion_tiles: the per-tile map of those points (occlusion_map). occlusion_now and
  // occlusion_cells: the last map reprojected onto this frame, per pixel and per cell
  // (occlusion_reproject).
  GrowBuffer occlusion_depth[2], occlusion_opaque_at, occlusion_behind, occlusion_partial, occlusion_now;
  GrowBuffer occlusion_cells, occlusion_tiles;
  bool occlusion_map_drawn = false;  // the frame being drawn writes a map (plan_frame_slices sizes occlusion_partial)
  int occlusion_read = 0;
  fm::View occlusion_view{};
  bool occlusion_valid = false;
  bool occlusion_counted = false;  // the last frame drew a map (last_stats reads its counter)
  // occlusion_behind's copy, queued on the stream before kMerged (a synchronous cudaMemcpy in
  // last_stats would take the legacy default stream, which waits for the process's other work).
  PinnedBuffer occlusion_behind_host;
  // The frame's depth grid (RenderOptions::depth_grid_cell; exact frames, depth_grid.cu) and its
  // copy, queued on the stream before kMerged as occlusion_behind's; depth_grid_cols 0: none drawn.
  GrowBuffer depth_grid;
  PinnedBuffer depth_grid_host;
  int depth_grid_cols = 0, depth_grid_rows = 0, depth_grid_cell = 0;
  // catgs (render_catgs.cpp): trails and frustum cache (per Gaussian) and its counters
  // (CatgsCounterSlot; the plan's totals among them).
  GrowBuffer trail_mean0_motion, trail_conic_q, trail_cov, trail_mask, cached, select_temp, catgs_counters;
  unsigned* host_catgs = nullptr;        // pinned [kHostCatgsSlots]
  cudaEvent_t catgs_readback = nullptr;  // M / outside flag copied to host_catgs
  cudaEvent_t plan_ready = nullptr;      // the key frame's slice totals copied to host_catgs
  SpeculationPlanner planner;
  // The last catgs frame's time is still to be reported to the planner's cost model (read at the
  // next frame's start, and only if its events are done: the report never waits on the GPU).
  bool cost_pending = false;
  // render_yuv420_at (cuda_renderer.cpp): I420 planes for a host target, and the conversion's
  // timing events.
  GrowBuffer yuv;
  PinnedBuffer yuv_host;  // the planes of a host target, on their way to it
  cudaEvent_t convert_start = nullptr, converted = nullptr;
  cudaEvent_t planes_ready = nullptr;  // a begun frame's planes are where its target wants them
  uint64_t key_entries = 0, key_visible = 0, key_capacity = 0;  // the open group's key frame
  int window = 0;
  bool key_frame = true;

  // Grows the buffers every frame of a scene of `n` Gaussians at this camera's size needs: the
  // per-chunk lists for the scene, the per-slot buffers for slot_chunks (at first a guess:
  // initial_slot_chunks), per tile and pixel.
  void ensure_frame_buffers(uint64_t n, uint32_t tiles, std::size_t pixels);
  // Grows the per-slot buffers (and, with `catgs`, the trails and frustum cache) to hold at least
  // `chunks` slot chunks, with tune::kGrowthFactor slack (`slack` false: exactly), never more than
  // the scene's chunks; contents are lost.
  void ensure_slots(uint64_t chunks, bool catgs, bool slack = true);
  uint64_t slots() const { return slot_chunks * fm::kChunkSize; }
  bool catgs_sized = false;  // the trails and frustum cache follow slot_chunks

  // Stages 2-4 after pre-processing, in two halves, for the frames that look at the counts before
  // listing (issue 35: a catgs key frame narrows its window, a frame over the budget is drawn in
  // passes; issue 61: a view that kept more chunks than the slots hold is pre-processed again).
  // `n`: the slots (slots()); `walk`: the chunks pre-processing kept (live_walk()).
  // count_render_list: the counts readback (the frame's sync; with !depth_first the chunks' scan
  // and the Gaussians' ends are queued behind it); emit_render_list: grows the list buffers for
  // `entries`, emits keys with `tests` (records kKeysEmitted), sorts (sets sorted_values, records
  // kSorted) and writes the tile ranges with `packing` (a pass: its whole frame's single-sort key,
  // so each tile's order is the single pass's). With `depth_first` the list is ordered by the
  // depth-first sort (depth_order.cu; the same list). The caller checks the render-list budget
  // (RenderBudgetError, renderer.h) between the two, before any list buffer grows.
  // `overflow`: stage 1 kept more chunks (`kept`) than the per-slot buffers hold: the caller
  // grows them (ensure_slots(kept)) and runs stage 1 again; nothing else of the frame is valid.
  struct ListCounts {
    uint64_t entries = 0, visible = 0;
    stages::DepthKeyPacking packing = fm::plain_key_packing();  // the single sort's, from the depths
    uint64_t kept = 0;
    bool overflow = false;
  };
  ListCounts count_render_list(uint64_t n, const stages::ChunkWalk& walk, const stages::CameraParams& cam,
                               bool depth_first);
  void emit_render_list(uint64_t n, const stages::ChunkWalk& walk, const stages::CameraParams& cam,
                        const stages::TileTests& tests, bool depth_first, uint64_t entries, uint64_t visible,
                        const stages::DepthKeyPacking& packing);

  // The split plan's buffers for `capacity` slices and `slots` partial slots over `tiles` tiles
  // (with `opaque_points`: the slices' own opaque points, occlusion culling), the per-tile state
  // set as task_split.h says where a buffer is new (plan_frame_slices; reserve_buffers).
  void ensure_slice_buffers(uint32_t tiles, uint64_t capacity, uint64_t slots, bool opaque_points);
  // Plans the split tasks of a frame of `entries` list entries and their order (task_split.cu,
  // paper sec. 3.4; after the tile ranges) and returns the slice capacity, the blocks the frame's
  // rasterize_slices launches (cuda_renderer.cpp). A pass of a frame drawn in passes gives its
  // frame's list length as `frame_entries` (the slice length is the frame's) and plans tiles
  // [first_tile, end_tile) only.
  uint64_t plan_frame_slices(uint32_t tiles, uint64_t entries, const SpeculationParams& sp, uint64_t frame_entries = 0,
                             uint32_t first_tile = 0, uint32_t end_tile = 0xffffffffu);

  // catgs key frames (render_catgs.cpp): grows the trail and frustum-cache buffers; measures M
  // between the key camera and the predicted next one (one 4-byte readback) and returns the
  // planner's W.
  void ensure_catgs_buffers();
  int measure_window(const stages::SceneView& scene, const stages::CameraParams& key, const stages::CameraParams& next,
                     float depth_threshold);

  // Views of the buffers as the stages take them.
  stages::Projected projected() const {
    return {splat.as<stages::Splat>(),    color.as<float4>(),       depth.as<float>(),         rect.as<ushort4>(),
            tiles_touched.as<uint32_t>(), tile_mask.as<uint32_t>(), chunk_total.as<uint32_t>()};
  }
  // Where preprocess lists the chunks it keeps, and the same list as later stages walk it.
  stages::LiveChunks live_chunk_list() const {
    return {live_chunks.as<uint32_t>(),
            reinterpret_cast<unsigned*>(counters.as<unsigned long long>() + kLiveChunkCount),
            live_keep.as<uint32_t>(),
            live_slot.as<uint32_t>(),
            slot_chunks,
            live_scan_temp.as<void>(),
            live_scan_temp.bytes()};
  }
  stages::ChunkWalk live_walk() const { return live_chunk_list().walk(); }
  stages::BigList big_list() const {
    // The 64-bit counter slot holds both 32-bit counts (big, huge).
    return {big.as<uint32_t>(), reinterpret_cast<unsigned*>(counters.as<unsigned long long>() + kBigCount),
            big.bytes() / sizeof(uint32_t), huge_part_count.as<uint32_t>()};
  }
  stages::Trails trails() const {
    return {trail_mean0_motion.as<float4>(), trail_conic_q.as<float4>(), trail_cov.as<float4>(),
            trail_mask.as<uint32_t>()};
  }
  stages::SlicePlan slice_plan() const {
    return {slice_range.as<uint2>(),       slice_tile.as<uint2>(),
            tile_plan.as<uint4>(),         catgs_counters.as<unsigned>() + kSliceTotals,
            saturated_from.as<unsigned>(), slices_done.as<unsigned>(),
            slot_finished.as<unsigned>()};
  }

  std::size_t bytes() const {
    std::size_t b = 0;
    for (const GrowBuffer* g : {&splat,
                                &color,
                                &depth,
                                &rect,
                                &tiles_touched,
                                &tile_mask,
                                &chunk_total,
                                &chunk_start,
                                &live_chunks,
                                &live_keep,
                                &live_slot,
                                &live_scan_temp,
                                &ends,
                                &scan_temp,
                                &big,
                                &huge_part_count,
                                &keys[0],
                                &keys[1],
                                &values[0],
                                &values[1],
                                &sort_temp,
                                &depth_index[0],
                                &depth_index[1],
                                &depth_keys[0],
                                &depth_keys[1],
                                &depth_count,
                                &depth_temp,
                                &ranges,
                                &heaviest_tile,
                                &tile_order,
                                &rgb,
                                &rgba8,
                                &counters,
                                &trail_mean0_motion,
                                &trail_conic_q,
                                &trail_cov,
                                &trail_mask,
                                &cached,
                                &select_temp,
                                &slice_range,
                                &slice_tile,
                                &tile_plan,
                                &slice_order,
                                &partials,
                                &saturated_from,
                                &slices_done,
                                &slot_finished,
                                &plan_scratch,
                                &catgs_counters,
                                &occlusion_depth[0],
                                &occlusion_depth[1],
                                &occlusion_opaque_at,
                                &occlusion_behind,
                                &occlusion_partial,
                                &occlusion_now,
                                &occlusion_cells,
                                &occlusion_tiles,
                                &yuv})
      b += g->bytes();
    return b;
  }
  void note_peak() { peak_bytes = std::max(peak_bytes, bytes()); }

  ~State() {
    if (host_counts) cudaFreeHost(host_counts);
    if (host_catgs) cudaFreeHost(host_catgs);
    if (catgs_readback) cudaEventDestroy(catgs_readback);
    if (plan_ready) cudaEventDestroy(plan_ready);
    if (convert_start) cudaEventDestroy(convert_start);
    if (converted) cudaEventDestroy(converted);
    if (planes_ready) cudaEventDestroy(planes_ready);
    for (cudaEvent_t& e : events)
      if (e) cudaEventDestroy(e);
    if (counts_ready) cudaEventDestroy(counts_ready);
    if (stream) cudaStreamDestroy(stream);
  }
};

}  // namespace catgs::cuda
