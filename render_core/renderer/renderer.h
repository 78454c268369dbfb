// The render-core interface the server and tools use; implemented by the CPU reference
// (cpu_renderer.h) and the CUDA core.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "camera/camera.h"
#include "scene/gaussian_model.h"
#include "speculation/speculation_params.h"
#include "colour/yuv420.h"

namespace catgs {

// vanilla: reference 3DGS (3-sigma square bounds, every touched tile, a tile's list blended whole).
// exact:   opacity-aware extent + exact ellipse-vs-tile test (render list = tiles really reached)
//          + load-aware task splitting (paper sec. 3.4): a tile of over twice the average load is
//          blended as slices and merged. Where a pixel's transmittance drops below 1e-4 inside a
//          later slice, that slice's Gaussians behind the stop still count, each weighted by less
//          than 1e-4 (the paper's higher termination threshold for later slices; RESULTS.md
//          measures it against the unsplit image). SpeculationParams::task_splitting = false
//          blends every tile whole.
// catgs:   exact + speculation, frustum/sort caches (paper sec. 3).
enum class Pipeline { vanilla, exact, catgs };

// "vanilla" | "exact" | "catgs" -> Pipeline; throws std::invalid_argument otherwise.
Pipeline parse_pipeline(const std::string& name);
const char* pipeline_name(Pipeline pipeline);

// A frame whose render list would exceed the budget (a std::length_error, as the 2^32 limit).
class RenderBudgetError : public std::length_error {
 public:
  using std::length_error::length_error;
};

// The per-frame render-list budget (issue 22): a scene of giant Gaussians lists every one of them
// in every tile (20 k Gaussians of log-scale 5 made 163 M entries, 4.5 GB and 18 s a 1080p frame),
// so the list a frame may build is bounded by the viewport, and refused before it is allocated.
// Rule: entries <= min(max(max_entries_per_tile x tiles, min_entries), max_bytes / bytes per entry,
// 2^32 - 1), with tiles = ceil(W / 16) x ceil(H / 16) and the core's bytes per entry (CPU: 28, the
// key, the value and the sort's pair). Defaults: 16384 entries a tile (134 M entries at 1080p:
// 1.6x the 7 M city's largest default catgs key-frame list there, 83.5 M in the window table of
// docs/history/render_core_speculation.md),
// at least 16 M entries (a whole scene in a thumbnail lists every Gaussian in its few tiles) and
// 4 GiB.
//
// The rule bounds what one pass lists, not what a legitimate view may show (issue 35: a view of
// the 7 M-Gaussian city at 1280x720 listed 59.35 M entries, just over the 59.0 M there). A frame
// over it is not refused but drawn in smaller pieces, the same on both cores:
// - catgs: a speculative key frame whose list is over the budget is planned again with half the
//   window (SpeculationPlanner::narrower_window), down to W = 0, an exact frame (FrameStats
//   window_narrowed).
// - exact, vanilla and catgs's W = 0 frames: drawn in passes of tiles (renderer/render_passes.h),
//   bands of whole tile rows (a run of one row's tiles where a row alone is over), each listing,
//   sorting and rasterizing only its tiles within the budget, into the one image, which equals
//   the single-pass image (every pass keeps the full frame's camera, sort key and split length).
//   FrameStats::passes counts them.
// RenderBudgetError is left for what passes cannot or must not draw:
// - giant Gaussians (issue 22's hostile scene): the listed Gaussians reach on average more than
//   1 / giant_share of the frame's tiles (20 k Gaussians of log-scale 5 reach all of them; the
//   real scenes' views list a few tiles per Gaussian, tests/unit/render_passes_test.cpp);
// - a frame that would take more than max_passes passes (the work a frame may cost stays
//   bounded: at most max_passes x max_entries entries);
// - a single tile whose own list is over the budget (no pass can hold it).
struct RenderListBudget {
  std::uint64_t max_entries_per_tile = 16384;
  std::uint64_t max_bytes = 4ull << 30;
  std::uint64_t min_entries = 1ull << 24;
  std::uint64_t max_passes = 16;   // 1: no passes, a frame over max_entries() is refused
  std::uint64_t giant_share = 16;  // 0: no giant-Gaussian refusal

  // The most entries a width x height frame (or one pass of it) may list with `bytes_per_entry`
  // bytes an entry.
  std::uint64_t max_entries(int width, int height, std::uint64_t bytes_per_entry) const;
  // Throws RenderBudgetError when `entries` exceeds max_entries(...); the message names the
  // entries, the bytes they would take, the budget and the rule.
  void check(std::uint64_t entries, int width, int height, std::uint64_t bytes_per_entry) const;
  // For a frame over max_entries(): throws RenderBudgetError (check()'s message) when its `listed`
  // Gaussians (those with entries) reach on average more than 1 / giant_share of the tiles. A
  // catgs key frame checks its trail list so (a trail is a few percent longer than the ellipse)
  // before narrowing its window, so a scene of giant Gaussians costs one pre-processing, not one
  // a window.
  void check_reach(std::uint64_t entries, std::uint64_t listed, int width, int height,
                   std::uint64_t bytes_per_entry) const;
  // For a frame over max_entries(): throws RenderBudgetError (check()'s message, and the reason)
  // unless it may be drawn in passes: check_reach(), and at most max_passes x max_entries()
  // entries.
  void check_passes(std::uint64_t entries, std::uint64_t listed, int width, int height,
                    std::uint64_t bytes_per_entry) const;
  // The error for a frame of `entries` entries over the budget, `why` appended to check()'s message.
  RenderBudgetError error(std::uint64_t entries, int width, int height, std::uint64_t bytes_per_entry,
                          const std::string& why) const;

  // Only the 2^32 - 1 limit of the 32-bit tile ranges, and no passes: for benchmarks and tests that
  // make lists past the server's budget on purpose (wide speculation windows, lists past 2^31
  // entries).
  static RenderListBudget unlimited() { return {UINT64_MAX, UINT64_MAX, 0, 1, 0}; }
};

struct RenderOptions {
  Pipeline pipeline = Pipeline::exact;
  glm::vec3 background{0.0f};     // linear RGB in [0, 1], composited behind the Gaussians
  SpeculationParams speculation;  // catgs; exact frames take task_splitting and min_slice_entries
  RenderListBudget list_budget;   // enforced by both cores before the list is allocated
  // Level of detail (forward_model/lod.h): the screen-space error bound tau, pixels, of the cut
  // through a scene's LOD tree; 0 = full detail (the leaves only). A scene without LOD ignores
  // it. The default is the largest bound measured that keeps >= 35 dB PSNR against full detail on
  // every compared frame (every 10th) of the 101- and 201-copy cities' 1080p fly-over
  // (docs/history/level_of_detail.md, "Second round", issue 37).
  float lod_error_px = 0.75f;
  // Occlusion culling (forward_model/occlusion.h; issue 72), exact frames only: a frame drops the
  // list entries that its renderer's last frame found behind its opaque pixels. The renderer keeps
  // one map (a session's last frame); set_options and a new scene drop it. Off here, so that a
  // renderer draws each frame alone; the server turns it on (--occlusion-cull).
  bool occlusion_culling = false;
  // The frame's depth grid (forward_model/depth_grid.h; issue 91), exact frames only: a vertex
  // every `depth_grid_cell` pixels (0: none), read with Renderer::last_depth_grid().
  int depth_grid_cell = 0;
};

// The last frame's depth grid (forward_model/depth_grid.h): cols x rows vertices, row-major, each
// the median depth (camera-space z, world units; +inf: no surface) at x = min(k cell, width),
// y = min(l cell, height). Empty (cols = 0) when the options asked for none or the frame was not
// an exact one.
struct DepthGrid {
  int cols = 0, rows = 0, cell = 0;
  std::vector<float> depth;  // [rows, cols]
};

// An image in host memory, row-major, top row first.
struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;      // [H, W, 3], unclamped composited colour
  std::vector<uint8_t> rgba8;  // [H, W, 4], clamp([0,1]) * 255 rounded, alpha 255
};

// Converts a float colour to 8 bits as the forward model says: clamp to [0, 1], * 255, round.
// NaN maps to 0: the comparisons are written so that NaN fails `v > 0` (a float-to-integer cast of
// NaN is undefined behaviour in C++).
inline uint8_t to_unorm8(float v) {
  v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;
  return static_cast<uint8_t>(v * 255.0f + 0.5f);
}

// Per-frame counters and stage times (milliseconds, wall clock on CPU, CUDA events on GPU).
struct FrameStats {
  std::size_t visible = 0;  // Gaussians that passed culling
  // Chunks pre-processed (exact and vanilla frames of both cores; catgs frames report 0): those of
  // the LOD cut that chunk culling kept (exact: in view, and not hidden whole by the last frame's
  // map).
  std::size_t chunks_preprocessed = 0;
  // Occlusion culling (RenderOptions::occlusion_culling): pre-processing read the last frame's
  // map, and this frame's list entries at or behind their tile's opaque point (its map's P:
  // entries that change no pixel by more than 1/255 in all; 0 without culling).
  bool occlusion_map_used = false;
  std::size_t entries_behind_opaque = 0;
  // The CPU core's measurement (CpuRenderer::count_changes, issue 72): list entries blended at a
  // pixel while its transmittance was above 1/255, and the Gaussians with such an entry (0 when
  // not measured).
  std::size_t entries_changing_pixels = 0, gaussians_changing_pixels = 0;
  // The same measurement's bound on what a map can drop (cpu/hidden_count.cpp): against this
  // frame's own per-pixel map, the Gaussians of the cut's chunks in view and those in chunks whose
  // screen box lies behind it, those in runs of 32 (a warp's share of a chunk) whose own bound's
  // box does, the listed Gaussians whose own ellipse box does, and the list entries whose box
  // within their tile does.
  std::size_t gaussians_preprocessed = 0, gaussians_in_hidden_chunks = 0, gaussians_in_hidden_groups = 0,
              gaussians_hidden_alone = 0, entries_hidden_pixels = 0;
  std::size_t render_list_length = 0;  // Gaussian-tile pairs (keys) rasterized
  double preprocess_ms = 0, keys_ms = 0, sort_ms = 0, ranges_ms = 0, rasterize_ms = 0;
  double merge_ms = 0;  // catgs with task splitting: composing the slices
  double total_ms = 0;
  // catgs pipeline (speculation, paper sec. 3.1-3.4); vanilla/exact frames are all key frames.
  bool key_frame = true;  // false: a sub-frame served from the frustum and sort caches
  int window = 0;         // W of the current group (0: no speculation)
  // A key frame first tried as a sub-frame of the open group: some on-screen Gaussian had left
  // its trail (the prediction missed), so the frame was drawn again as a key frame.
  bool subframe_rejected = false;
  std::size_t cached = 0;  // Gaussians in the frustum cache
  std::size_t slices = 0;  // rasterization tasks after task splitting (tiles when unsplit)
  // The render-list budget (RenderListBudget, issue 35). passes: 1, or the passes of tiles a frame
  // over the budget was drawn in (render_list_length then sums them; longest_pass is the longest
  // pass's list, render_list_length with one pass). window_narrowed: a catgs key frame whose list
  // at planned_window (the planner's W) was over the budget, drawn with `window` < planned_window
  // instead (0: as an exact frame).
  int passes = 1;
  std::size_t longest_pass = 0;
  bool window_narrowed = false;
  int planned_window = 0;
  // The catgs cost model (SpeculationParams::cost_model; SpeculationPlanner's figures, 0 where it
  // has none): predicted_gain, on a key frame that opened a group, the exact frame's cost over
  // the group's expected cost a frame; measured_gain, on the frame that closed a group, that
  // group's measured exact-equivalent time over its own.
  double predicted_gain = 0.0, measured_gain = 0.0;
};

// What a renderer's buffers hold (issue 73): Gaussians for its per-Gaussian buffers (the CUDA
// core's slots, records.h Projected; the CPU core's whole scene) and render-list entries for its
// list buffers (one pass).
struct BufferShape {
  std::uint64_t gaussians = 0;
  std::uint64_t list_entries = 0;
};

class Renderer {
 public:
  virtual ~Renderer() = default;
  // "cpu" or "cuda".
  virtual std::string name() const = 0;
  // Renders `camera` (its width x height) into `out`, reusing out's storage. Throws
  // std::invalid_argument for a camera with a non-positive or > 8192 size or non-finite values.
  virtual void render(const Camera& camera, Image& out) = 0;
  // Renders a camera the client posed at `time_s` (seconds, client clock). The catgs pipeline
  // feeds its motion predictor with it; the others ignore the time.
  virtual void render_at(const Camera& camera, double time_s, Image& out) {
    (void)time_s;
    render(camera, out);
  }
  // Renders a camera posed at `time_s` (as render_at()) and writes the frame as BT.709
  // limited-range I420 (yuv420.h) into `out`, whose size must be the camera's. Returns the
  // milliseconds spent on the colour conversion (wall clock on the CPU, CUDA events on the GPU).
  // This default renders into host memory and converts on the CPU (rgba_to_yuv420_bt709) into a
  // host target. The CUDA core overrides it: the frame is converted on the GPU, a host target
  // receives only the planes (1.5 bytes a pixel), a device target is written in place (the
  // NVENC hw frame path). Throws std::invalid_argument for a target of another size or with bad
  // planes, or a device target on a renderer that has no device; render errors as render().
  virtual double render_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out);
  // render_yuv420_at() in two halves, so that a render lane can queue one view's frame and start
  // another's while the GPU draws it (server/render/render_scheduler.h, "Frames in flight"):
  // begin_yuv420_at() queues the frame (it may wait for the frame's counts mid-frame, never for
  // its planes); finish_yuv420() waits for the planes, writes them into the target begin was given
  // and returns what render_yuv420_at() returns. Between the two the target and this renderer
  // belong to the frame: no call but finish_yuv420() (then last_stats()). Either throws as
  // render_yuv420_at() does; a begin that threw leaves nothing to finish. std::logic_error for a
  // begin while a frame is begun, or a finish without one. This default draws the whole frame in
  // begin (the CPU core has nothing to overlap) and finish returns its conversion time.
  virtual void begin_yuv420_at(const Camera& camera, double time_s, const Yuv420Target& out);
  virtual double finish_yuv420();
  // Whether finish_yuv420() would return without waiting for the device (a frame is begun); no
  // wait. The default's begin drew the whole frame: true. The CUDA core asks the frame's last event
  // and throws CudaError where the device reports an error (finish_yuv420 would meet it too).
  virtual bool frame_ready() const { return true; }
  // Stats of the last render().
  virtual const FrameStats& last_stats() const = 0;
  // The last frame's depth grid (RenderOptions::depth_grid_cell), valid as last_stats() is.
  virtual const DepthGrid& last_depth_grid() const {
    static const DepthGrid none;
    return none;
  }
  virtual const RenderOptions& options() const = 0;
  virtual void set_options(const RenderOptions& options) = 0;
  // Device bytes this renderer's own buffers hold now (GrowBuffers: they only grow), not its
  // scene's copy; 0 on the CPU core, whose buffers are host memory (renderer/device_memory.h
  // estimates what they would take on a device). The server raises a session's memory
  // reservation to it after each frame (issue 61).
  virtual std::uint64_t device_buffer_bytes() const { return 0; }
  // Allocates now what frames of width x height need, with room for `shape` as given, no growth
  // slack added (a shape read from buffer_shape holds its slack already) and never more
  // Gaussians than the scene has (issue 73: a server session holds its buffers from the door, so
  // its frames allocate only to grow past them).
  // Throws OutOfMemoryError (base/allocation_faults.h) where they do not fit; what was allocated
  // stays, and the renderer is whole. The default does nothing.
  virtual void reserve_buffers(int width, int height, const BufferShape& shape) {
    (void)width, (void)height, (void)shape;
  }
  // What the buffers hold now ({0, 0} by default).
  virtual BufferShape buffer_shape() const { return {}; }

 protected:
  // begin_yuv420_at()'s bookkeeping, shared by the overrides: throws std::logic_error when a frame
  // is begun already (begin_frame) or none is (end_frame).
  void begin_frame();
  void end_frame();

 private:
  Image yuv_source_;               // the default render_yuv420_at()'s host frame, reused between frames
  bool frame_begun_ = false;       // begin_yuv420_at() ran and finish_yuv420() has not
  double begun_convert_ms_ = 0.0;  // the default begin's conversion time, for its finish
};

// Creates a renderer by name: "cpu", "cuda" or "auto" (CUDA if built and a device is usable, else
// CPU; `why` receives a one-line reason). The model must outlive the renderer. A CUDA renderer
// renders on CUDA device `gpu` (the server spreads sessions over its GPUs); the CPU renderer
// ignores it. Throws std::runtime_error when "cuda" is asked for and unavailable.
std::unique_ptr<Renderer> make_renderer(const std::string& kind, std::shared_ptr<const GaussianModel> model,
                                        const RenderOptions& options, std::string* why = nullptr, int gpu = 0);

// CUDA devices this process sees (CUDA_VISIBLE_DEVICES applies); 0 when built without CUDA or
// without a driver or device. Never throws.
int cuda_device_count();

// How CUDA renderers' host threads wait for their GPU: "spin" (the driver's default) or "block"
// (asleep until the GPU is done, leaving the core to other work such as a host's encoders);
// cuda::set_host_wait. Returns false without CUDA, for another word, or where a device refused.
// Never throws.
bool set_cuda_host_wait(const std::string& wait);

// Device memory in use on CUDA device `gpu` (total - free, every process's), bytes; 0 when built
// without CUDA or on error. Never throws.
std::size_t cuda_device_memory_used(int gpu);
// Device memory of CUDA device `gpu` in all, bytes; 0 when built without CUDA or on error. Never
// throws.
std::size_t cuda_device_memory_total(int gpu);
// Device memory the driver reports free on CUDA device `gpu` now (cudaMemGetInfo: what every
// process leaves), bytes; UINT64_MAX (unknown) when built without CUDA or on error. Never throws.
std::uint64_t cuda_device_memory_free(int gpu);
// Where the upload of a CUDA renderer's scene went (cuda::DeviceScene::upload_times), one line for
// a log: "codes check A ms, chunk bounds B ms, copies C ms (D GiB at E GB/s)"; empty for another
// renderer or when built without CUDA. Never throws.
std::string cuda_upload_report(const Renderer& renderer);

}  // namespace catgs
