// The CUDA render core (docs/DESIGN.md "Render core"): the CPU reference's stages on the GPU
// (render_core/cuda/, one .cu per stage), the vanilla, exact and catgs pipelines chosen at run time.
//
// catgs (paper sec. 3; docs/DESIGN.md "Speculation"; render_core/cuda/render_catgs.cpp): the same
// decisions as the CPU reference's cpu::SpeculativeRenderer (both use SpeculationPlanner). A key
// frame measures M (one 4-byte readback), pre-processes the speculation window (trails), emits,
// sorts, ranges, selects the frustum cache and plans the split tasks (the counts readback below); a
// sub-frame recomputes the cached Gaussians' features at its pose and rasterizes the key frame's
// slices, then reads back one flag: if an on-screen Gaussian left its trail, the frame is rendered
// again as a key frame. Syncs: key frame 2 (1 without a window), sub-frame 1.
//
// Ownership: a DeviceScene holds one copy of a GaussianModel in device memory and is shared,
// read-only, by any number of CudaRenderers (shared_ptr<const DeviceScene>). Each CudaRenderer
// owns a CUDA stream and reusable device buffers that grow when a frame needs more (by 1.25x) and
// are never freed between frames: a steady trace allocates nothing.
//
// Host-device synchronisation per frame (vanilla, exact): ONE, in render_device(): after the scan of per-Gaussian
// tile counts, 16 bytes (render list length, visible count) come back to the host, because CUB's
// radix sort takes its item count from the host and the list buffers may have to grow first.
// render(camera, Image&) adds a second one, the download of the image to host memory.
// last_stats() waits for the frame's last event (the caller chooses to pay for timing).
//
// Errors: every CUDA call and launch is checked; failures throw CudaError naming the call, the
// source line and the CUDA error. A render list past 2^32 - 1 entries (32-bit tile ranges and
// Gaussian indices) throws std::length_error before any allocation; a scene past 2^32 - 1
// Gaussians throws std::length_error at upload; running out of device memory throws CudaError
// from the cudaMalloc that failed, with the byte count in its message.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "base/cuda_error.h"
#include "forward_model/chunk_bounds.h"
#include "forward_model/compact_codes.h"
#include "forward_model/occlusion.h"
#include "renderer/renderer.h"

struct CUstream_st;  // cudaStream_t without the CUDA headers

namespace catgs::cuda {

// True when a CUDA device of compute capability >= 7.0 can be used; `reason` receives the device
// name and capability, or why not (no driver, no device, ...). Never throws.
bool device_usable(std::string* reason);

// Name, multiprocessor count and memory of the current device ("NVIDIA H100 80GB HBM3, 132 SMs,
// 79.1 GiB"). Throws CudaError.
std::string device_description();

// Device bytes a render-list entry takes, as RenderListBudget (renderer.h) counts them: two key
// buffers (8 bytes each: the sort ping-pongs) and two value buffers (4 each). The CPU core's is
// 28 (cpu_renderer.h); neither counts the sort's scratch.
inline constexpr std::uint64_t kBytesPerListEntry = 24;

// Device memory in use on the current device (total - free), bytes. Throws CudaError.
std::size_t device_memory_used();
// Device memory of the current device in all, bytes. Throws CudaError.
std::size_t device_memory_total();

// CUDA devices visible to this process (CUDA_VISIBLE_DEVICES applies), 0 when there is no
// driver or device. Never throws.
int device_count();

// How a host thread waits for every device this process sees (a stream or event sync).
enum class HostWait {
  spin,   // the driver's default (cudaDeviceScheduleAuto: it spins while the process has fewer
          // contexts than cores)
  block,  // sleeps on a synchronisation primitive (cudaDeviceScheduleBlockingSync)
};
// Sets it on every device. Set before a device's first use where possible (later it overwrites
// that device's flags). Returns false when a device refused. Never throws.
// The device flag governs stream syncs only: cudaEventSynchronize busy-waits on an event created
// without cudaEventBlockingSync whatever the flag says (CUDA runtime API, cudaEventSynchronize). So
// renderers made after set_host_wait(block) create the events their host waits on with it and
// poll each briefly before sleeping on it (renderer_state.h wait_for; issue 92: the frame's
// readback wait in a lane's begin spun for as long as the GPU's queue held it; RESULTS.md, "The
// server's cores by thread").
bool set_host_wait(HostWait wait);
// What set_host_wait last set (spin until it is called).
HostWait host_wait();
// The flags for an event a host thread waits on: cudaEventDisableTiming, and cudaEventBlockingSync
// while host_wait() is block.
unsigned host_wait_event_flags();

// Makes `device` the calling thread's current CUDA device for the guard's lifetime, and restores
// the previous one after. Every CudaRenderer and DeviceScene call that touches the GPU holds one,
// so a thread may drive renderers on several devices (the server's render lanes do). Throws
// CudaError for a device that does not exist.
class DeviceGuard {
 public:
  explicit DeviceGuard(int device);
  ~DeviceGuard();
  DeviceGuard(const DeviceGuard&) = delete;
  DeviceGuard& operator=(const DeviceGuard&) = delete;

 private:
  int previous_ = 0;
  bool changed_ = false;
};

// One copy of a scene in device memory (layouts as GaussianModel). Immutable after upload.
class DeviceScene {
 public:
  // Uploads `model` (validated shapes) to CUDA device `device`. Throws std::length_error past
  // 2^32 - 1 Gaussians, std::invalid_argument for inconsistent arrays, CudaError when device
  // memory runs out or the device does not exist.
  static std::shared_ptr<const DeviceScene> upload(const GaussianModel& model, int device = 0);
  ~DeviceScene();
  DeviceScene(const DeviceScene&) = delete;
  DeviceScene& operator=(const DeviceScene&) = delete;

  const std::string& name() const { return name_; }
  std::size_t size() const { return n_; }
  int sh_degree() const { return sh_degree_; }
  std::size_t bytes() const { return bytes_; }  // device memory held
  int device() const { return device_; }        // the CUDA device it lives on
  // Device pointers: means [N, 3], log_scales [N, 3], rotations [N, 4], opacity_logits [N] as
  // floats; sh [N, K, 3] as IEEE binary16 bits, rounded on upload (forward_model/sh_storage.h).
  const float* means() const { return means_; }
  const float* log_scales() const { return log_scales_; }
  const float* rotations() const { return rotations_; }
  const float* opacity_logits() const { return opacity_logits_; }
  const uint16_t* sh() const { return sh_; }
  // [fm::chunk_count(N)] the bound of each run of fm::kChunkSize Gaussians (chunk culling).
  const fm::ChunkBounds* chunks() const { return chunks_; }
  // [fm::chunk_count(N)] the LOD tree's nodes (forward_model/lod.h), nullptr without LOD.
  const fm::LodNode* lod() const { return lod_; }
  // The compact layout (issue 74): where the model's GaussianModel::codes still match its arrays
  // (compact_codes_match), the codes (forward_model/compact_codes.h) in place of log_scales,
  // rotations, opacity_logits and sh (then null): rotation and log-scale codes [N] (uint32), colour
  // codes [N, 4] (DC red, green, blue, alpha), SH rest codes [N, sh_code_bytes], the chunks'
  // ranges, the 256 opacity logits of the alpha codes. 45 bytes a Gaussian at SH degree 2 with
  // the float means, against 98. All null in the float layout.
  bool compact() const { return rotation_codes_ != nullptr; }
  const uint32_t* rotation_codes() const { return rotation_codes_; }
  const uint32_t* scale_codes() const { return scale_codes_; }
  const uint8_t* colour_codes() const { return colour_codes_; }
  const uint8_t* sh_codes() const { return sh_codes_; }
  uint32_t sh_code_bytes() const { return sh_code_bytes_; }
  const fm::ChunkRanges* chunk_ranges() const { return chunk_ranges_; }
  const float* opacity_lut() const { return opacity_lut_; }
  // Where the upload's time went (wall clock, milliseconds), for the server's log and RESULTS.md
  // "Compact scene": the compact codes' check against the arrays (compact_codes_match) and the
  // chunk bounds on the host, then the copies to the device (cudaMalloc and the staged copies of
  // `copied_bytes`, until the last arrived).
  struct UploadTimes {
    double check_ms = 0.0, bounds_ms = 0.0, copy_ms = 0.0;
    std::size_t copied_bytes = 0;
  };
  const UploadTimes& upload_times() const { return upload_times_; }

 private:
  DeviceScene() = default;
  std::string name_;
  std::size_t n_ = 0, bytes_ = 0;
  int sh_degree_ = 0, device_ = 0;
  float* means_ = nullptr;
  float* log_scales_ = nullptr;
  float* rotations_ = nullptr;
  float* opacity_logits_ = nullptr;
  uint16_t* sh_ = nullptr;
  fm::ChunkBounds* chunks_ = nullptr;
  fm::LodNode* lod_ = nullptr;
  uint32_t* rotation_codes_ = nullptr;
  uint32_t* scale_codes_ = nullptr;
  uint8_t* colour_codes_ = nullptr;
  uint8_t* sh_codes_ = nullptr;
  uint32_t sh_code_bytes_ = 0;
  fm::ChunkRanges* chunk_ranges_ = nullptr;
  float* opacity_lut_ = nullptr;
  UploadTimes upload_times_;
};

// A rendered frame in device memory, valid until the renderer's next frame; ready once `stream`
// has reached the end of the frame (work queued on `stream` after render_device() sees it).
struct DeviceFrame {
  int width = 0, height = 0;
  const float* rgb = nullptr;       // [H, W, 3] unclamped composited colour
  const uint32_t* rgba8 = nullptr;  // [H, W] R | G << 8 | B << 16 | 255 << 24
  CUstream_st* stream = nullptr;
};

// Two implementation choices of the CUDA core, for the tests that compare them (tests/gpu) and
// nothing else:
// - depth_first_sort: sort the render list depth first (the visible Gaussians by depth, then the
//   entries stably by tile alone; depth_order.cu) instead of one radix sort: the same list,
//   entry for entry, as a single sort on plain [tile | depth] keys (catgs key frames); exact
//   lists' single sort uses the 32-bit key (forward_model/key_packing.h), which orders depths
//   within its quantum by index instead, so the two differ there (>= 60 dB). Unset, it follows the pipeline: on for catgs, whose
//   key-frame trail lists are long, off for exact, whose lists are short (docs/history/
//   render_core_sort_and_keys.md, "The depth-first sort"). vanilla, and catgs key
//   frames without a window, always sort the single way.
// - tile_culling: catgs rasterizers blend only the trail-list entries whose ellipse reaches the
//   tile at this frame's pose (blend.cuh blend_range_culled); off blends every entry: the same
//   image, bit for bit.
struct CudaOptions {
  std::optional<bool> depth_first_sort;
  bool tile_culling = true;
};

class CudaRenderer final : public Renderer {
 public:
  // Renders on its scene's device (DeviceScene::device): every call below makes that device
  // current for its duration (DeviceGuard), whatever the calling thread's device was.
  // Throws std::invalid_argument for a null scene or speculation parameters validate() refuses
  // (speculation_params.h), CudaError when the stream or events cannot be created.
  CudaRenderer(std::shared_ptr<const DeviceScene> scene, const RenderOptions& options,
               const CudaOptions& cuda_options = {});
  ~CudaRenderer() override;

  std::string name() const override { return "cuda"; }
  std::uint64_t device_buffer_bytes() const override;
  // The frame, per-slot (shape.gaussians rounded up to whole chunks), list and sort, and I420
  // buffers of a width x height frame (renderer.h). Throws OutOfMemoryError as a frame would.
  void reserve_buffers(int width, int height, const BufferShape& shape) override;
  BufferShape buffer_shape() const override;
  // render_device() then a download into `out` (rgb and rgba8, as the CPU renderer fills them).
  void render(const Camera& camera, Image& out) override;
  // render_device_at() then a download into `out`.
  void render_at(const Camera& camera, double time_s, Image& out) override;
  // render_device_at(), then the GPU colour conversion (yuv420_convert.cu) into `out`: a device
  // target (current device, primary context) is written in place; for a host target the planes
  // are converted into a device buffer and copied back (w * h * 1.5 bytes). Ends with a stream
  // sync, so the planes are complete on return. Returns the conversion kernel's time (events).
  // Throws std::invalid_argument for a bad target; CudaError as render_device().
  double render_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) override;
  // render_yuv420_at() in halves (renderer.h): begin queues the frame, its conversion and, for a
  // host target, the planes' copy into page-locked memory (the frame's counts sync is its only
  // wait); finish waits for the converted event (a device target) or the copy (a host one) and
  // copies the planes to the target's strides.
  void begin_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out) override;
  double finish_yuv420() override;
  // Whether the begun frame's planes are done (an event query; no wait); CudaError on a device
  // error.
  bool frame_ready() const override;
  // Renders `camera` into this renderer's device image; one host-device sync (see above).
  // Throws std::invalid_argument for a bad camera, std::length_error for an oversized render
  // list, OutOfMemoryError where a buffer cannot grow, CudaError for other CUDA failures. After
  // any of them the renderer is whole (issue 73): the catgs group and the occlusion map are
  // dropped, and the next frame renders as a key frame, unculled.
  // catgs: the renderer's own clock advances 1 / F_target a call (as render_device_at()).
  DeviceFrame render_device(const Camera& camera);
  // As render_device(), for a camera the client posed at `time_s` (seconds, client clock): the
  // catgs pipeline feeds its motion predictor with it; vanilla and exact ignore it.
  DeviceFrame render_device_at(const Camera& camera, double time_s);
  // Stats of the last frame; waits for that frame to finish (stage times from CUDA events).
  const FrameStats& last_stats() const override;
  // Waits for the frame's last event (as last_stats) the first time after a frame.
  const DepthGrid& last_depth_grid() const override;
  const RenderOptions& options() const override { return options_; }
  void set_options(const RenderOptions& options) override;
  // Switches to another scene; buffers are kept and grow if it needs more.
  void set_scene(std::shared_ptr<const DeviceScene> scene);
  const std::shared_ptr<const DeviceScene>& scene() const { return scene_; }

  CUstream_st* stream() const;

  // What the renderer holds and did, for benchmarks and tests. heaviest_tile_entries waits for
  // the last frame and copies 4 bytes back (outside the frame's timing).
  struct Diagnostics {
    std::size_t buffer_bytes = 0;       // device memory the reusable buffers hold now
    std::size_t peak_buffer_bytes = 0;  // the most they held
    std::size_t allocations = 0;        // buffer (re)allocations since construction
    int syncs_last_frame = 0;           // host-device synchronisations in the last render_device()
    // Entries of the last frame's longest slice (exact and catgs: of a split plan, where a heavy
    // tile is several slices; catgs sub-frames: their key frame's; vanilla: its heaviest tile).
    // One block walks it alone, so it bounds the rasterization time.
    std::size_t heaviest_tile_entries = 0;
    // Chunks (fm::kChunkSize Gaussians) the last frame's pre-processing kept after chunk culling
    // (exact, vanilla, or a catgs key frame's speculative pre-processing), of `chunks`; a catgs
    // sub-frame reports its key frame's.
    std::size_t chunks_kept = 0, chunks = 0;
  };
  Diagnostics diagnostics() const;

 private:
  struct State;
  DeviceFrame render_full(const Camera& camera);  // vanilla, exact
  // After a frame that threw, or buffers that grew outside a frame (reserve_buffers): what the
  // next frame must not trust (the catgs group and its caches, the occlusion map, a pending cost
  // report) is dropped.
  void drop_inter_frame_state();
  // A whole frame through the exact (or vanilla) stages after kStart: pre-processing, counts, and
  // stages 2-5 in one pass, or, over the list budget, in passes of tiles (renderer/render_passes.h,
  // as cpu::render_full_frame), each sorted with the frame's key and split with its slice length.
  // Sets stats_'s visible, render_list_length, passes and longest_pass. Throws RenderBudgetError
  // as draw_in_passes. Used by render_full and by catgs key frames without a window (which sort
  // in one radix sort: depth_first false). `occlusion`: the last frame's map for pre-processing
  // (with its depths over this frame's tiles: fm::entry_hidden; null: none); `draw_map`: write this frame's map into
  // State::occlusion_depth[1 - occlusion_read] (exact frames; buffers sized by the caller).
  void draw_full_frame(const Camera& camera, bool exact, bool early_termination, bool depth_first,
                       const fm::OcclusionMap& occlusion = {}, bool draw_map = false);
  DeviceFrame render_catgs(const Camera& camera, double time_s);  // render_catgs.cpp
  void catgs_key_frame(const Camera& camera);                     // render_catgs.cpp
  bool catgs_sub_frame(const Camera& camera);                     // render_catgs.cpp
  void report_cost();  // the last catgs frame's time to the planner's cost model (render_catgs.cpp)
  // render_catgs.cpp; abandon: device flag, draw nothing when it is set (or null); trail_list:
  // the list is a key frame's trail list (tile-culled per pose), not an exact one.
  void catgs_rasterize(const Camera& camera, uint32_t blocks, const unsigned* abandon, bool trail_list);
  void download(const DeviceFrame& frame, Image& out);
  std::shared_ptr<const DeviceScene> scene_;
  Yuv420Target begun_target_{};  // begin_yuv420_at's target, for finish_yuv420
  int begun_width_ = 0, begun_height_ = 0;
  RenderOptions options_;
  std::unique_ptr<State> state_;
  mutable FrameStats stats_;
  mutable bool stats_ready_ = true;
  mutable DepthGrid depth_grid_;  // last_depth_grid's copy of the frame's
  mutable bool depth_grid_ready_ = true;
  CudaOptions cuda_options_;
  bool depth_first_sort() const {
    return cuda_options_.depth_first_sort.value_or(options_.pipeline == Pipeline::catgs);
  }
};

// The DeviceScene of `model` on `device`: uploaded on the first call, then the same one for as
// long as any renderer holds it (a process-wide cache keyed by the model's address and the
// device, thread-safe), so many sessions over one scene share one copy per GPU. Throws as
// DeviceScene::upload.
std::shared_ptr<const DeviceScene> shared_device_scene(const std::shared_ptr<const GaussianModel>& model,
                                                       int device = 0);

// A CudaRenderer over shared_device_scene(model, device) (renderer_factory.cpp).
std::unique_ptr<Renderer> make_cuda_renderer(std::shared_ptr<const GaussianModel> model, const RenderOptions& options,
                                             int device = 0);

}  // namespace catgs::cuda
