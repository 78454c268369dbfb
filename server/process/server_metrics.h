// Process-wide metrics for /metrics (Prometheus text exposition format 0.0.4). Any thread.
//
// Names (all times in seconds, as Prometheus expects):
//   catgs_info{renderer,encoder,pipeline} 1          what this server runs
//   catgs_connections, catgs_sessions                 gauges
//   catgs_*_total                                     counters (see prometheus_text)
//   catgs_queue_seconds        pose received -> render start
//   catgs_render_seconds{kind="key"|"sub"}            render of a key frame / cached sub-frame
//   catgs_convert_seconds      RGB -> YUV 4:2:0 (0 when the frame arrives as YUV)
//   catgs_encode_seconds       encoder
//   catgs_encode_psnr_db       the encoder's picture each frame (FrameTimings.encode_psnr_db; x264)
//   catgs_encoder_steps_down_total  encoders rebuilt a step down the preset ladder (host filling)
//   catgs_core_refusals_total  visitors refused at the door: the cores could not encode their
//                              stream at the ladder's floor (--x264-floor)
//   catgs_send_seconds         frame handed to the transport -> fully written to the socket
//   catgs_speculation_window   W of the speculation group of each rendered frame (0: none)
//   catgs_speculation_gain     the catgs cost model's predicted and measured gain a group
//   catgs_pose_to_frame_seconds  end to end, client-reported (Pose.shown_latency_ms): pose sent ->
//                              its frame shown, on the client's clock
//   catgs_session_fps          each session's frame rate over each Stats interval (about 1 s)
//                              that had frames (a histogram: no per-session label to grow)
//   catgs_gpu_sessions{gpu}, catgs_gpu_render_seconds{gpu}   per GPU of --gpus (CUDA renderer):
//                              sessions rendering there, and their render times
//   catgs_gpu_splats_per_second{gpu}  the GPU's throughput the auto splat budget reads
//                              (render/lod_bound.h): the best of any one frame, Gaussians/s
//   catgs_frame_lod_bound_px   the level-of-detail bound each frame drew at, px (issue 72)
//   catgs_lod_over_budget_frames_total  frames drawn at --lod-max-error whose cut still passed the
//                              splat budget; catgs_splat_budget_refusals_total  visitors refused
//                              at the door for it (ERROR_SERVER_FULL)
//   catgs_refused_upgrades_total{reason}  WebSocket upgrades refused before the handshake
//   catgs_timeouts_total{kind}            connections closed for silence: no Hello, or a silent session,
//                                         or for a scene that did not load in time (scene_load)
//   catgs_rate_limited_total{kind}        sessions ended (or Hellos refused) for going past a rate limit
//   catgs_unauthorized_total{what}        wrong or missing tokens: Hello, /metrics
//   catgs_link_rate_cuts_total{cause}     link control's cuts by what read as congestion
//   catgs_scenes_loaded, catgs_scene_bytes  scenes in memory now and their models' host bytes
//                              (process/scene_store.h; a GPU copy per device besides)
//   catgs_scene_loads_total, catgs_scene_load_failures_total, catgs_scene_unloads_total
//                              loads finished / failed, scenes unloaded for --scene-memory-mb
//   catgs_lod_builds_running, catgs_lod_build_progress  levels of detail being built at load (no
//                              valid LOD file) and the running build's progress, 0 to 1
//   catgs_lod_builds_total, catgs_lod_files_written_total  builds finished, LOD files written
//   catgs_heap_in_use_bytes    what the C library's allocator holds for the server now (glibc
//                              mallinfo2, all arenas; -1 elsewhere): a leak raises its floor, as
//                              RSS's (which keeps pages the allocator did not give back) may not
//   catgs_exports_running      video exports rendering now (session/session_export.h)
//   catgs_exports_total{result}  exports ended: sent (the file went to the page), failed,
//                              cancelled (Cancel, or the page closed), refused (ExportVideoRequest
//                              refused: role, caps, one running)
//   catgs_export_frames_total  frames rendered for exports
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <cstdint>
#include <mutex>
#include <ostream>
#include <string>
#include <vector>

namespace catgs::server {

// A Prometheus histogram: cumulative buckets with upper bounds `le`, _sum and _count. A mutex
// keeps one exposition consistent (the +Inf bucket always equals _count).
class Histogram {
 public:
  // `upper_bounds`: increasing, finite. Throws std::invalid_argument otherwise.
  explicit Histogram(std::vector<double> upper_bounds);
  // Adds one sample (any unit; the stage histograms use seconds). Thread-safe.
  void observe(double value);
  // Writes the _bucket, _sum and _count series of `name`; `labels` is empty or `k="v",...`
  // (no braces), placed before `le`.
  void write(std::ostream& out, const std::string& name, const std::string& labels = "") const;
  // Samples observed so far.
  std::uint64_t count() const;

  // Bucket bounds for stage times, seconds: 0.5 ms .. 1.024 s, doubling.
  static std::vector<double> stage_seconds();

 private:
  std::vector<double> bounds_;
  mutable std::mutex mutex_;
  std::vector<std::uint64_t> counts_;  // per bucket, not cumulative; last = above every bound
  double sum_ = 0;
  std::uint64_t count_ = 0;
};

struct ServerMetrics {
  // What the server runs (set once at start-up, before any session).
  std::string renderer, encoder, pipeline;

  std::atomic<std::int64_t> connections_open{0};  // WebSocket connections now
  std::atomic<std::int64_t> sessions_open{0};     // connections past a valid Hello, now
  std::atomic<std::uint64_t> sessions_total{0};
  std::atomic<std::uint64_t> frames_total{0};      // frames handed to the transport
  std::atomic<std::uint64_t> key_frames_total{0};  // IDR access units among them
  std::atomic<std::uint64_t> bytes_total{0};       // Frame payload bytes
  std::atomic<std::uint64_t> poses_total{0};
  std::atomic<std::uint64_t> poses_skipped_total{0};  // replaced by a newer pose (latest wins)
  // Rendered frames dropped before their encode: they would have missed their display slot and
  // a newer pose was waiting (session/frame_pacing.h).
  std::atomic<std::uint64_t> deadline_skips_total{0};
  // Encoders rebuilt because the live sessions changed the threads they should get (an IDR each).
  std::atomic<std::uint64_t> encoder_rebuilds_total{0};
  std::atomic<std::uint64_t> encoder_steps_down_total{0};
  std::atomic<std::uint64_t> core_refusals_total{0};  // visitors refused at the door for the cores (--x264-floor)
  // Content-aware rate probes ended (--bits-per-pixel auto: a scene and size measured).
  std::atomic<std::uint64_t> content_rate_probes_total{0};
  // Frames lost: a pose pending, or a frame rendering or encoding, when its session ended or
  // failed (a pose replaced by a newer one is a skip, poses_skipped_total, not a drop).
  std::atomic<std::uint64_t> dropped_frames_total{0};
  std::atomic<std::uint64_t> session_errors_total{0};          // sessions ended with an Error
  std::atomic<std::uint64_t> render_budget_refusals_total{0};  // frames over the render-list budget
  std::atomic<std::uint64_t> memory_refusals_total{0};         // visitors no GPU's memory could hold
  std::atomic<std::uint64_t> render_out_of_memory_total{0};    // frames whose buffers could not grow
  // Frames drawn anyway after a buffer could not grow (issue 73): in passes within the list
  // buffers held, or at a coarser cut (FramePipeline's memory fallbacks).
  std::atomic<std::uint64_t> render_memory_fallbacks_total{0};
  // Visitors refused at the door because the driver's free memory, not the accounting, bound.
  std::atomic<std::uint64_t> memory_refusals_driver_total{0};
  std::atomic<std::uint64_t> render_key_frames_total{0};  // full pre-process renders
  std::atomic<std::uint64_t> render_sub_frames_total{0};  // catgs sub-frames from the caches
  std::atomic<std::uint64_t> render_rekeys_total{0};      // catgs key frames first tried as sub-frames
  // Encoders opened as x264 because --encoder auto found NVENC unusable (start-up + sessions).
  std::atomic<std::uint64_t> encoder_fallbacks_total{0};
  // --adaptive-quality (session/adaptive_quality.h): level changes and refine frames.
  std::atomic<std::uint64_t> quality_down_total{0}, quality_up_total{0}, refine_frames_total{0};
  // --link-control (session/link_rate.h): sessions whose bitrate the link holds down now, the
  // cuts made, and the clients' frame receipts the controller read (Pose.received_ms).
  std::atomic<std::int64_t> sessions_link_limited{0};
  std::atomic<std::uint64_t> link_rate_decreases_total{0};
  // The same cuts by what read as congestion (LinkRate::Cause: send_delay, receipts, round_trip).
  std::atomic<std::uint64_t> link_rate_cuts_total[3]{};
  std::atomic<std::uint64_t> frame_receipts_total{0};

  // Scenes (process/scene_store.h, kept by the store): loaded now, their host bytes, and loads
  // that finished, loads that failed and unloads under --scene-memory-mb.
  std::atomic<std::int64_t> scenes_loaded{0}, scene_bytes{0};
  std::atomic<std::uint64_t> scene_loads_total{0}, scene_load_failures_total{0}, scene_unloads_total{0};
  // Level of detail (process/scene_with_lod.h): builds running now and the running one's progress
  // (per mille), builds finished, LOD files written beside their scenes.
  std::atomic<std::int64_t> lod_builds_running{0}, lod_build_permille{0};
  std::atomic<std::uint64_t> lod_builds_total{0}, lod_files_written_total{0};

  // Video export from the page: the render slots taken now (each export holds one while it
  // renders; --export-max-concurrent bounds it), how exports ended, and their frames.
  std::atomic<int> exports_running{0};
  enum class ExportEnd { sent, failed, cancelled, refused };
  std::atomic<std::uint64_t> exports_total[4]{};
  std::atomic<std::uint64_t> export_frames_total{0};
  void count(ExportEnd e) { exports_total[static_cast<int>(e)]++; }

  // Hardening (issue 22). Each array is indexed by the enum named beside it.
  std::atomic<std::uint64_t> refused_upgrades_total[4]{};  // transport.h Refusal
  enum class Timeout { hello, silent, scene_load };
  std::atomic<std::uint64_t> timeouts_total[3]{};
  enum class Limit { hello, auth, ping, key_frame, resize, quality, depth, save, export_video };
  std::atomic<std::uint64_t> rate_limited_total[9]{};
  enum class Unauthorized { hello, metrics };
  std::atomic<std::uint64_t> unauthorized_total[2]{};
  void count(Timeout t) { timeouts_total[static_cast<int>(t)]++; }
  void count(Limit l) { rate_limited_total[static_cast<int>(l)]++; }
  void count(Unauthorized u) { unauthorized_total[static_cast<int>(u)]++; }

  Histogram queue_seconds{Histogram::stage_seconds()};
  Histogram render_key_seconds{Histogram::stage_seconds()};
  Histogram render_sub_seconds{Histogram::stage_seconds()};
  Histogram convert_seconds{Histogram::stage_seconds()};
  Histogram encode_seconds{Histogram::stage_seconds()};
  Histogram encode_psnr_db{{20, 25, 28, 30, 31, 32, 33, 34, 36, 38, 40, 45}};
  Histogram send_seconds{Histogram::stage_seconds()};
  Histogram speculation_window{{0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32}};
  // The LOD bound of each frame, px (0: full detail or no LOD): the ladder's x sqrt(2) steps of 2 px.
  Histogram frame_lod_bound_px{{0, 1, 1.42, 2.01, 2.83, 4.01, 5.66, 8.01, 11.32, 16.01, 32.01}};
  std::atomic<std::uint64_t> lod_over_budget_frames_total{0};
  std::atomic<std::uint64_t> splat_budget_refusals_total{0};
  // catgs cost model: each opened group's predicted gain and each closed group's measured one
  // (FrameStats predicted_gain / measured_gain; exact's time over the group's).
  Histogram speculation_predicted_gain{{0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0, 3.0}};
  Histogram speculation_measured_gain{{0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0, 3.0}};
  Histogram pose_to_frame_seconds{Histogram::stage_seconds()};
  Histogram session_fps{{1, 5, 10, 15, 20, 25, 30, 45, 60, 90, 120, 240}};
  // Each session's device-memory reservation at each Stats, bytes (GpuAssignment).
  Histogram session_device_bytes{{64.0 * (1 << 20), 128.0 * (1 << 20), 256.0 * (1 << 20), 512.0 * (1 << 20),
                                  768.0 * (1 << 20), 1024.0 * (1 << 20), 1536.0 * (1 << 20), 2048.0 * (1 << 20),
                                  3072.0 * (1 << 20), 4096.0 * (1 << 20), 6144.0 * (1 << 20), 8192.0 * (1 << 20)}};
  // Each memory slot's accounting (the GPUs, or the CPU renderer's host slot), read at exposition.
  struct MemoryRow {
    std::string slot;                                      // "0", "1", ... a GPU; "host" the CPU renderer's allowance
    std::uint64_t capacity = 0, scenes = 0, reserved = 0;  // bytes (capacity 0: unlimited)
    std::uint64_t held = 0;                                // what the sessions' buffers hold
    std::uint64_t driver_free = UINT64_MAX;                // the driver's free bytes (UINT64_MAX: not read)
  };
  std::function<std::vector<MemoryRow>()> device_memory;

  // Per GPU (set once at start-up, before any session, by set_gpus): the CUDA devices, their
  // session counts (GpuAssignment::sessions, read at exposition) and render times.
  void set_gpus(std::vector<int> devices, std::function<std::vector<std::int64_t>()> sessions);
  // Adds a render time on `device` (one of set_gpus' devices; others are ignored). Thread-safe.
  void observe_gpu_render(int device, double seconds);
  // The GPU's throughput as the auto splat budget reads it (render/lod_bound.h): the most
  // Gaussians per millisecond the GPU has shown, one frame's Gaussians over its render time times
  // the frames that were rendering on the GPU with it (`in_flight`, itself included): render lanes
  // share the GPU, so a frame that waited behind three others' kernels took about four times as
  // long while the GPU drew four frames (without that factor a loaded GPU measured slower than
  // it is, and the auto budget collapsed to the ladder's top: docs/history/level_of_detail.md "Level
  // of detail in the server"). Units: Gaussians, milliseconds, frames (in_flight >= 1). Frames of under 100 k Gaussians are not counted (their fixed costs hide the
  // rate). Thread-safe; 0 until known.
  void observe_gpu_throughput(int device, std::uint64_t gaussians, double render_ms, double in_flight = 1.0);
  // Frames rendering on `device` now: begin returns the count with this frame, end the count
  // before it leaves (the mean of the two is the frame's in_flight above).
  int gpu_render_begin(int device);
  int gpu_render_end(int device);
  double gpu_splats_per_ms(int device) const;
  // A frame on `device` drew at the ceiling (--lod-max-error) over its splat budget at `now_ms`
  // (a steady clock, ms), with gpu_sessions(device) sessions there; gpu_budget_short: one did
  // within `within_ms` before `now_ms` and the GPU has as many sessions now (visitors who left
  // since made room), so it holds no more visitors at the picture's floor (render/lod_bound.h).
  // Thread-safe.
  void note_gpu_budget_short(int device, std::int64_t now_ms);
  static std::int64_t steady_now_ms();  // the clock those take
  bool gpu_budget_short(int device, std::int64_t now_ms, std::int64_t within_ms) const;
  // Sessions rendering on `device` now (GpuAssignment::sessions; 0 for one not in set_gpus).
  std::int64_t gpu_sessions(int device) const;

  // The Prometheus exposition text.
  std::string prometheus_text() const;

 private:
  std::vector<int> gpu_devices_;
  std::function<std::vector<std::int64_t>()> gpu_sessions_;
  std::vector<std::unique_ptr<Histogram>> gpu_render_seconds_;              // by index in gpu_devices_
  std::unique_ptr<std::atomic<std::int64_t>[]> gpu_splats_per_ms_;          // by index, rounded down
  std::unique_ptr<std::atomic<int>[]> gpu_in_flight_;                       // by index
  std::unique_ptr<std::atomic<std::int64_t>[]> gpu_budget_short_at_;        // by index: ms, INT64_MIN never
  std::unique_ptr<std::atomic<std::int64_t>[]> gpu_budget_short_sessions_;  // by index: sessions then
  int gpu_index(int device) const;
};

}  // namespace catgs::server
