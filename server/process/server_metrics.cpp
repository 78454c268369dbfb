#include "process/server_metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <sstream>
#include <stdexcept>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace catgs::server {

Histogram::Histogram(std::vector<double> upper_bounds) : bounds_(std::move(upper_bounds)) {
  for (std::size_t i = 0; i < bounds_.size(); ++i)
    if (!std::isfinite(bounds_[i]) || (i > 0 && bounds_[i] <= bounds_[i - 1]))
      throw std::invalid_argument("Histogram: bucket bounds must be finite and increasing");
  counts_.assign(bounds_.size() + 1, 0);
}

std::vector<double> Histogram::stage_seconds() {
  std::vector<double> b;
  for (double s = 0.0005; s < 1.1; s *= 2) b.push_back(s);
  return b;
}

void Histogram::observe(double value) {
  // Bucket i holds bounds_[i - 1] < value <= bounds_[i] (Prometheus `le`).
  const auto i = static_cast<std::size_t>(std::lower_bound(bounds_.begin(), bounds_.end(), value) - bounds_.begin());
  std::lock_guard<std::mutex> lock(mutex_);
  counts_[i]++;
  sum_ += value;
  count_++;
}

std::uint64_t Histogram::count() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return count_;
}

void Histogram::write(std::ostream& out, const std::string& name, const std::string& labels) const {
  const std::string sep = labels.empty() ? "" : labels + ",";
  std::lock_guard<std::mutex> lock(mutex_);
  std::uint64_t cumulative = 0;
  for (std::size_t i = 0; i < bounds_.size(); ++i) {
    cumulative += counts_[i];
    out << name << "_bucket{" << sep << "le=\"" << bounds_[i] << "\"} " << cumulative << '\n';
  }
  out << name << "_bucket{" << sep << "le=\"+Inf\"} " << count_ << '\n';
  const std::string braces = labels.empty() ? "" : "{" + labels + "}";
  out << name << "_sum" << braces << ' ' << sum_ << '\n';
  out << name << "_count" << braces << ' ' << count_ << '\n';
}

namespace {

// Bytes the C library's allocator has handed out and not had back, over all arenas (glibc's
// mallinfo2: in-use chunks plus mmapped ones); -1 where unknown. Unlike RSS it does not keep the
// pages an arena grew into and did not give back, so its floor rises only with what is still held.
std::int64_t heap_in_use_bytes() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 m = mallinfo2();
  return static_cast<std::int64_t>(m.uordblks + m.hblkhd);
#else
  return -1;
#endif
}

}  // namespace

std::string ServerMetrics::prometheus_text() const {
  std::ostringstream o;
  o.precision(10);
  auto head = [&o](const char* name, const char* type, const char* help) {
    o << "# HELP " << name << ' ' << help << "\n# TYPE " << name << ' ' << type << '\n';
  };
  auto put = [&](const char* name, const char* type, const char* help, auto value) {
    head(name, type, help);
    o << name << ' ' << value << '\n';
  };
  head("catgs_info", "gauge", "What this server runs (value always 1).");
  o << "catgs_info{renderer=\"" << renderer << "\",encoder=\"" << encoder << "\",pipeline=\"" << pipeline << "\"} 1\n";
  put("catgs_connections", "gauge", "Open WebSocket connections.", connections_open.load());
  put("catgs_sessions", "gauge", "Open sessions (after Hello).", sessions_open.load());
  put("catgs_sessions_total", "counter", "Sessions opened.", sessions_total.load());
  put("catgs_frames_total", "counter", "Frames sent.", frames_total.load());
  put("catgs_key_frames_total", "counter", "IDR frames sent.", key_frames_total.load());
  put("catgs_frame_bytes_total", "counter", "Encoded frame bytes sent.", bytes_total.load());
  put("catgs_poses_total", "counter", "Poses received.", poses_total.load());
  put("catgs_poses_skipped_total", "counter", "Poses replaced before rendering.", poses_skipped_total.load());
  put("catgs_deadline_skips_total", "counter",
      "Rendered frames dropped before encoding: past their display slot with a newer pose waiting.",
      deadline_skips_total.load());
  put("catgs_encoder_rebuilds_total", "counter", "Encoders rebuilt for a new thread share as sessions joined or left.",
      encoder_rebuilds_total.load());
  put("catgs_encoder_steps_down_total", "counter",
      "Encoders rebuilt a step down the x264 preset ladder (sessions joined): a cheaper, worse picture.",
      encoder_steps_down_total.load());
  put("catgs_core_refusals_total", "counter",
      "Visitors refused at the door: the cores could not encode their stream at the x264 ladder's floor "
      "(--x264-floor).",
      core_refusals_total.load());
  put("catgs_content_rate_probes_total", "counter",
      "Content-aware rate probes ended (--bits-per-pixel auto): a scene's rate cap measured at a size.",
      content_rate_probes_total.load());
  put("catgs_dropped_frames_total", "counter",
      "Frames lost: rendered or being rendered for a session that ended or failed, or a pose pending "
      "when its session ended (poses replaced by a newer one are catgs_poses_skipped_total).",
      dropped_frames_total.load());
  put("catgs_session_errors_total", "counter", "Sessions ended with an Error.", session_errors_total.load());
  put("catgs_render_budget_refusals_total", "counter",
      "Frames refused because their render list would exceed the budget (RenderListBudget); the "
      "session ends with ERROR_INVALID_ARGUMENT.",
      render_budget_refusals_total.load());
  put("catgs_memory_refusals_total", "counter",
      "Visitors refused (ERROR_SERVER_FULL) because no GPU's memory could hold their session's buffers.",
      memory_refusals_total.load());
  put("catgs_memory_refusals_driver_total", "counter",
      "Of catgs_memory_refusals_total: those where what the driver reports free bound (another "
      "process holds the GPU's memory), not the server's accounting.",
      memory_refusals_driver_total.load());
  put("catgs_lod_over_budget_frames_total", "counter",
      "Frames drawn at --lod-max-error whose cut still held more Gaussians than the splat budget.",
      lod_over_budget_frames_total.load());
  put("catgs_splat_budget_refusals_total", "counter",
      "Visitors refused (ERROR_SERVER_FULL) because their GPU's sessions already drew at --lod-max-error "
      "over the splat budget.",
      splat_budget_refusals_total.load());
  put("catgs_render_out_of_memory_total", "counter",
      "Frames dropped because a session's buffers could not grow, even in passes and at a coarser "
      "cut (the session lives on).",
      render_out_of_memory_total.load());
  put("catgs_render_memory_fallbacks_total", "counter",
      "Frames drawn after a buffer could not grow: in passes within the list buffers held, or at a "
      "coarser level-of-detail cut.",
      render_memory_fallbacks_total.load());
  put("catgs_encoder_fallbacks_total", "counter",
      "Encoders opened as x264 because --encoder auto found NVENC unusable.", encoder_fallbacks_total.load());
  put("catgs_quality_down_total", "counter", "Adaptive quality: a session stepped its resolution down.",
      quality_down_total.load());
  put("catgs_quality_up_total", "counter", "Adaptive quality: a session stepped its resolution back up.",
      quality_up_total.load());
  put("catgs_sessions_link_limited", "gauge",
      "Sessions whose stream bitrate their link holds below the policy's rate now (--link-control).",
      sessions_link_limited.load());
  put("catgs_link_rate_decreases_total", "counter",
      "Link control: a session's bitrate cut because its frames backed up, its receipts showed a queue or its "
      "round trip grew.",
      link_rate_decreases_total.load());
  put("catgs_frame_receipts_total", "counter",
      "Link control: clients' frame receipts (Pose.received_ms) matched to a frame sent and read by the rate "
      "controller (0 while no client sends them: its round trip alone then).",
      frame_receipts_total.load());
  put("catgs_refine_frames_total", "counter",
      "Still views: the last pose drawn again at full size and the stream's crf when the camera stopped.",
      refine_frames_total.load());
  put("catgs_scenes_loaded", "gauge", "Scenes in memory (--scene; loaded on first use).", scenes_loaded.load());
  put("catgs_scene_bytes", "gauge", "Host bytes of the loaded scenes' models (each GPU holds a copy besides).",
      scene_bytes.load());
  put("catgs_scene_loads_total", "counter", "Scene loads that finished (start-up and first use).",
      scene_loads_total.load());
  put("catgs_scene_load_failures_total", "counter", "Scene loads that failed (their waiting sessions got an Error).",
      scene_load_failures_total.load());
  put("catgs_scene_unloads_total", "counter", "Unused scenes unloaded to stay within --scene-memory-mb.",
      scene_unloads_total.load());
  put("catgs_lod_builds_running", "gauge", "Scenes whose level of detail is being built now (no valid LOD file).",
      lod_builds_running.load());
  put("catgs_lod_build_progress", "gauge", "The running level-of-detail build's progress, 0 to 1.",
      static_cast<double>(lod_build_permille.load()) / 1000.0);
  put("catgs_lod_builds_total", "counter", "Levels of detail built at load (the LOD file was missing or stale).",
      lod_builds_total.load());
  put("catgs_lod_files_written_total", "counter", "LOD files written beside their scenes (--lod write).",
      lod_files_written_total.load());
  put("catgs_heap_in_use_bytes", "gauge",
      "Bytes the C library's allocator holds for the server now, all arenas (glibc mallinfo2; -1: unknown).",
      heap_in_use_bytes());
  put("catgs_exports_running", "gauge", "Video exports rendering now (at most --export-max-concurrent).",
      exports_running.load());
  put("catgs_export_frames_total", "counter", "Frames rendered for video exports.", export_frames_total.load());
  head("catgs_render_frames_total", "counter",
       "Frames rendered: kind=key (full pre-process) or sub (catgs sub-frame from the caches).");
  o << "catgs_render_frames_total{kind=\"key\"} " << render_key_frames_total.load() << '\n'
    << "catgs_render_frames_total{kind=\"sub\"} " << render_sub_frames_total.load() << '\n';
  put("catgs_render_rekeys_total", "counter",
      "catgs key frames first tried as sub-frames and rejected (a Gaussian left its trail).",
      render_rekeys_total.load());

  auto labelled = [&](const char* name, const char* help, const char* label, const auto& counters,
                      std::initializer_list<const char*> values) {
    head(name, "counter", help);
    std::size_t i = 0;
    for (const char* v : values) o << name << '{' << label << "=\"" << v << "\"} " << counters[i++].load() << '\n';
  };
  labelled("catgs_refused_upgrades_total",
           "WebSocket upgrades refused before the handshake: version (not 13), origin (not allowed), per_ip "
           "(--max-connections-per-ip), pre_hello (--max-pre-hello).",
           "reason", refused_upgrades_total, {"version", "origin", "per_ip", "pre_hello"});
  labelled("catgs_timeouts_total",
           "Connections closed for silence: hello (no Hello in --hello-timeout-ms), silent (no message in "
           "--silent-timeout-ms), scene_load (the scene not loaded in --scene-load-timeout-ms).",
           "kind", timeouts_total, {"hello", "silent", "scene_load"});
  labelled("catgs_rate_limited_total", "Hellos refused and sessions ended for going past a --rate-limits limit.",
           "kind", rate_limited_total,
           {"hello", "auth", "ping", "key_frame", "resize", "quality", "depth", "save", "export"});
  labelled("catgs_exports_total",
           "Video exports ended: sent (the file went to the page), failed, cancelled (Cancel, or the page closed), "
           "refused (the request was refused).",
           "result", exports_total, {"sent", "failed", "cancelled", "refused"});
  labelled("catgs_unauthorized_total", "Wrong or missing tokens: in a Hello, or for /metrics.", "what",
           unauthorized_total, {"hello", "metrics"});
  labelled("catgs_link_rate_cuts_total",
           "Link control's cuts (catgs_link_rate_decreases_total) by what read as congestion: send_delay (a frame "
           "the socket held), receipts (the clients' receipts' queue), round_trip (TCP's round trip, no receipts).",
           "cause", link_rate_cuts_total, {"send_delay", "receipts", "round_trip"});

  head("catgs_queue_seconds", "histogram", "Pose received -> render start.");
  queue_seconds.write(o, "catgs_queue_seconds");
  head("catgs_render_seconds", "histogram", "Render time by kind (key frame or sub-frame).");
  render_key_seconds.write(o, "catgs_render_seconds", "kind=\"key\"");
  render_sub_seconds.write(o, "catgs_render_seconds", "kind=\"sub\"");
  head("catgs_convert_seconds", "histogram", "RGB -> YUV 4:2:0 conversion.");
  convert_seconds.write(o, "catgs_convert_seconds");
  head("catgs_encode_seconds", "histogram", "Encoder time per frame.");
  encode_seconds.write(o, "catgs_encode_seconds");
  head("catgs_encode_psnr_db", "histogram",
       "The encoder's picture each frame: the coded frame against the frame it was given, PSNR dB (x264).");
  encode_psnr_db.write(o, "catgs_encode_psnr_db");
  head("catgs_send_seconds", "histogram", "Frame handed to the transport -> written to the socket.");
  send_seconds.write(o, "catgs_send_seconds");
  head("catgs_frame_lod_bound_px", "histogram",
       "The level-of-detail bound each frame drew at, pixels (0: full detail or no LOD; the splat budget raises "
       "it up to --lod-max-error).");
  frame_lod_bound_px.write(o, "catgs_frame_lod_bound_px");
  head("catgs_speculation_window", "histogram", "Speculation window W of each rendered frame (0: no speculation).");
  speculation_window.write(o, "catgs_speculation_window");
  head("catgs_speculation_gain", "histogram",
       "catgs cost model: exact's frame time over a speculation group's, kind=predicted when the group "
       "opened, kind=measured when it closed.");
  speculation_predicted_gain.write(o, "catgs_speculation_gain", "kind=\"predicted\"");
  speculation_measured_gain.write(o, "catgs_speculation_gain", "kind=\"measured\"");
  head("catgs_pose_to_frame_seconds", "histogram",
       "End to end, as clients report it (Pose.shown_latency_ms): pose sent -> its frame shown.");
  pose_to_frame_seconds.write(o, "catgs_pose_to_frame_seconds");
  head("catgs_session_fps", "histogram", "Frames per second of each session over each Stats interval with frames.");
  session_fps.write(o, "catgs_session_fps");
  head("catgs_session_device_bytes", "histogram",
       "Each session's device-memory reservation at each Stats: its estimate, or its buffers where more.");
  session_device_bytes.write(o, "catgs_session_device_bytes");
  if (device_memory) {
    const std::vector<MemoryRow> rows = device_memory();
    const std::pair<const char*, std::uint64_t MemoryRow::*> gauges[] = {{"capacity", &MemoryRow::capacity},
                                                                         {"scene", &MemoryRow::scenes},
                                                                         {"session", &MemoryRow::reserved},
                                                                         {"held", &MemoryRow::held}};
    for (const auto& [what, field] : gauges) {
      const std::string name = "catgs_device_memory_" + std::string(what) + "_bytes";
      const std::string help =
          std::string("Device memory of each GPU (or the CPU renderer's allowance, slot=\"host\"): ") +
          (field == &MemoryRow::capacity ? "what scenes and sessions may hold (0: unlimited)"
           : field == &MemoryRow::scenes ? "its scene copies"
           : field == &MemoryRow::held   ? "what its sessions' render buffers hold now"
                                         : "its sessions' reservations");
      head(name.c_str(), "gauge", help.c_str());
      for (const MemoryRow& r : rows)
        o << "catgs_device_memory_" << what << "_bytes{slot=\"" << r.slot << "\"} " << r.*field << '\n';
    }
    head("catgs_device_memory_driver_free_bytes", "gauge",
         "What the driver reports free on each GPU (cudaMemGetInfo: every process's use counted), read "
         "at exposition; absent for the CPU renderer.");
    for (const MemoryRow& r : rows)
      if (r.driver_free != UINT64_MAX)
        o << "catgs_device_memory_driver_free_bytes{slot=\"" << r.slot << "\"} " << r.driver_free << '\n';
  }
  if (!gpu_devices_.empty()) {
    const std::vector<std::int64_t> sessions = gpu_sessions_ ? gpu_sessions_() : std::vector<std::int64_t>{};
    head("catgs_gpu_sessions", "gauge", "Open sessions rendering on each GPU (--gpus).");
    for (std::size_t k = 0; k < gpu_devices_.size(); ++k)
      o << "catgs_gpu_sessions{gpu=\"" << gpu_devices_[k] << "\"} " << (k < sessions.size() ? sessions[k] : 0) << '\n';
    head("catgs_gpu_render_seconds", "histogram", "Render time per frame on each GPU (--gpus).");
    for (std::size_t k = 0; k < gpu_devices_.size(); ++k)
      gpu_render_seconds_[k]->write(o, "catgs_gpu_render_seconds", "gpu=\"" + std::to_string(gpu_devices_[k]) + "\"");
    head("catgs_gpu_splats_per_second", "gauge",
         "The best Gaussians per second of render each GPU showed (a frame's, times the frames rendering with it).");
    for (std::size_t k = 0; k < gpu_devices_.size(); ++k)
      o << "catgs_gpu_splats_per_second{gpu=\"" << gpu_devices_[k] << "\"} " << gpu_splats_per_ms_[k].load() * 1000
        << '\n';
  }
  return o.str();
}

void ServerMetrics::set_gpus(std::vector<int> devices, std::function<std::vector<std::int64_t>()> sessions) {
  gpu_devices_ = std::move(devices);
  gpu_sessions_ = std::move(sessions);
  gpu_render_seconds_.clear();
  for (std::size_t k = 0; k < gpu_devices_.size(); ++k)
    gpu_render_seconds_.push_back(std::make_unique<Histogram>(Histogram::stage_seconds()));
  gpu_splats_per_ms_ = std::make_unique<std::atomic<std::int64_t>[]>(gpu_devices_.size());
  gpu_in_flight_ = std::make_unique<std::atomic<int>[]>(gpu_devices_.size());
  gpu_budget_short_at_ = std::make_unique<std::atomic<std::int64_t>[]>(gpu_devices_.size());
  gpu_budget_short_sessions_ = std::make_unique<std::atomic<std::int64_t>[]>(gpu_devices_.size());
  for (std::size_t k = 0; k < gpu_devices_.size(); ++k) {
    gpu_splats_per_ms_[k] = 0;
    gpu_in_flight_[k] = 0;
    gpu_budget_short_at_[k] = INT64_MIN;
    gpu_budget_short_sessions_[k] = 0;
  }
}

int ServerMetrics::gpu_render_begin(int device) {
  const int k = gpu_index(device);
  return k < 0 ? 1 : gpu_in_flight_[k].fetch_add(1) + 1;
}

int ServerMetrics::gpu_render_end(int device) {
  const int k = gpu_index(device);
  return k < 0 ? 1 : gpu_in_flight_[k].fetch_sub(1);
}

int ServerMetrics::gpu_index(int device) const {
  for (std::size_t k = 0; k < gpu_devices_.size(); ++k)
    if (gpu_devices_[k] == device) return static_cast<int>(k);
  return -1;
}

void ServerMetrics::observe_gpu_render(int device, double seconds) {
  const int k = gpu_index(device);
  if (k >= 0) gpu_render_seconds_[k]->observe(seconds);
}

void ServerMetrics::observe_gpu_throughput(int device, std::uint64_t gaussians, double render_ms, double in_flight) {
  const int k = gpu_index(device);
  if (k < 0 || gaussians < 100000 || !(render_ms > 0.0)) return;
  const auto rate = static_cast<std::int64_t>(static_cast<double>(gaussians) * std::max(1.0, in_flight) / render_ms);
  std::atomic<std::int64_t>& best = gpu_splats_per_ms_[k];
  std::int64_t seen = best.load();
  while (rate > seen && !best.compare_exchange_weak(seen, rate)) {}
}

std::int64_t ServerMetrics::steady_now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void ServerMetrics::note_gpu_budget_short(int device, std::int64_t now_ms) {
  const int k = gpu_index(device);
  if (k < 0) return;
  gpu_budget_short_sessions_[k] = gpu_sessions(device);
  gpu_budget_short_at_[k] = now_ms;
}

bool ServerMetrics::gpu_budget_short(int device, std::int64_t now_ms, std::int64_t within_ms) const {
  const int k = gpu_index(device);
  if (k < 0) return false;
  const std::int64_t at = gpu_budget_short_at_[k].load();
  return at != INT64_MIN && now_ms - at <= within_ms && gpu_sessions(device) >= gpu_budget_short_sessions_[k].load();
}

double ServerMetrics::gpu_splats_per_ms(int device) const {
  const int k = gpu_index(device);
  return k < 0 ? 0.0 : static_cast<double>(gpu_splats_per_ms_[k].load());
}

std::int64_t ServerMetrics::gpu_sessions(int device) const {
  const int k = gpu_index(device);
  if (k < 0 || !gpu_sessions_) return 0;
  const std::vector<std::int64_t> s = gpu_sessions_();
  return static_cast<std::size_t>(k) < s.size() ? s[k] : 0;
}

}  // namespace catgs::server
