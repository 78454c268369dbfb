// catgs-loadgen's measurements and their report: what one session saw, the per-session and
// total summaries (percentiles, rates), a human table and JSON. Pure functions; no I/O but the
// strings they return.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace catgs::loadgen {

// The p-th percentile (p in [0, 100]) of `values` by linear interpolation between closest ranks
// (NumPy's default): sorted x[0..n-1], rank r = p / 100 * (n - 1), x[floor r] + (r - floor r) *
// (x[floor r + 1] - x[floor r]). 0 for an empty input. Throws std::invalid_argument for p
// outside [0, 100].
double percentile(std::vector<double> values, double p);

// Server-side stage times of a session's frames, from Frame.timings (ms): sums and a count.
struct StageSums {
  double queue = 0, render = 0, convert = 0, encode = 0, send = 0, total = 0;
  double lane_wait = 0;      // of queue: FrameTimings.lane_wait_ms
  std::uint64_t frames = 0;  // frames summed (send: frames with previous_send_ms > 0)
  std::uint64_t sends = 0;
  std::uint64_t render_key = 0;                  // frames whose render was a key frame (catgs: full pre-process)
  std::uint64_t render_rekey = 0;                // catgs key frames first tried as sub-frames (re-keys)
  double window = 0;                             // sum of the frames' speculation windows W
  double predicted_gain = 0, measured_gain = 0;  // sums over the groups that carried them
  std::uint64_t predicted_groups = 0, measured_groups = 0;
  // Level of detail (FrameTimings.lod_error_px, .splats): sums over frames, and the largest bound.
  double lod_error_px = 0, lod_error_px_max = 0, splats = 0;
  // The encoder's picture (FrameTimings.encode_psnr_db, dB): its sum over the frames that carried
  // one, and their count (x264 streams; 0 for NVENC and AV1).
  double encode_psnr_db = 0;
  std::uint64_t encode_psnr_frames = 0;
  double encode_thread_cpu = 0;  // FrameTimings.encode_thread_cpu_ms summed over frames
  // FrameTimings.lane_{lod,begin,finish}_cpu_ms summed over frames: the render lane's CPU.
  double lane_lod_cpu = 0, lane_begin_cpu = 0, lane_finish_cpu = 0;
  // The renderer's own stage times (FrameTimings.stage_*_ms: frame, preprocess, keys, sort,
  // ranges, rasterize), summed over frames, and per render lane its frames and frame times.
  static constexpr const char* kStageNames[6] = {"frame", "preprocess", "keys", "sort", "ranges", "rasterize"};
  double stage[6] = {};
  struct Lane {
    std::uint64_t frames = 0;
    double frame_ms = 0;
  };
  std::map<int, Lane> lanes;
  void add(const StageSums& o);
};

// What one session saw. Filled by run_load_session (load_session.h).
struct SessionResult {
  int index = 0;                      // session number in the run, from 0
  std::string trace;                  // trace spec it replayed
  int width = 0, height = 0;          // frame size the Welcome named
  int size_changes = 0;               // Frames whose size differed from the one before (adaptive quality)
  int min_width = 0, min_height = 0;  // the smallest frame size seen
  std::string session_id, renderer, encoder, pipeline, scene;  // from Welcome
  double run_seconds = 0;                                      // poses were sent for this long
  std::uint64_t poses_sent = 0;
  std::uint64_t frames = 0;      // Frame messages received
  std::uint64_t idr_frames = 0;  // among them, IDR access units
  std::uint64_t av1_frames = 0;  // among them, AV1 temporal units (Frame.codec; the rest H.264)
  int codec_changes = 0;         // Frames whose codec differed from the one before
  std::uint64_t decoded = 0;     // pictures the decoder produced (with --decode)
  std::uint64_t bytes = 0;       // payload bytes received
  // Poses sent that got no frame, in two kinds: `skipped`, replaced by a newer pose that did get
  // one (latest pose wins: the server's Stats.poses_skipped, by design); `dropped`, lost: no
  // newer pose was answered either (the session ended or the server stopped answering).
  std::uint64_t skipped = 0;
  std::uint64_t dropped = 0;
  std::uint64_t server_skipped = 0;  // Stats.poses_skipped in the server's last Stats (a cross-check)
  // The link (Stats.bitrate_cap_kbps, link_kbps): Stats messages that said the link held the
  // stream below the policy's rate, and the lowest cap they gave (0: never limited).
  int link_limited_stats = 0;
  std::uint32_t link_cap_kbps_min = 0;
  double link_kbps_last = 0;  // the server's last estimate of the link's rate (0: none)
  // Frames read after the client was 50 ms or more away from its socket (no receipt for them
  // unless --receipts 2), and receipts put on poses.
  std::uint64_t late_reads = 0, receipts_sent = 0;
  // The most device memory the server's Stats said this session held (Stats.device_memory_mib).
  std::uint32_t device_memory_mib_max = 0;
  // Frames the server drew after one of this session's buffers could not grow (the sum of
  // Stats.memory_fallback_frames; issue 73).
  std::uint64_t memory_fallback_frames = 0;
  std::string stream_encoder;  // the last Stats.encoder: the preset the stream ended at ("x264 ultrafast")
  std::uint64_t stale = 0;     // frames later than the stale bound, or older than one shown
  std::uint64_t errors = 0;    // server Error, lost connection, undecodable frame
  std::string first_error;
  // The server refused the Hello (Error instead of Welcome): no session ran. `refusal` names the
  // ErrorCode and reason.
  bool refused = false;
  std::string refusal;
  std::vector<double> latency_ms;  // pose sent -> frame received (decoded with --decode), after warm-up
  // Every frame, warm-up included (LoadSessionConfig::timeline, --timeline): seconds from the
  // session's first pose to the frame's arrival, its latency (ms), size and payload bytes, and the
  // part of the latency spent in the server (FrameTimings.total_ms: pose received -> frame handed
  // to the transport; the rest is the way there, the transport's queue, the link and the decode).
  struct FrameRecord {
    double t_s, latency_ms;
    int width, height;
    std::size_t bytes;
    double server_ms;
  };
  std::vector<FrameRecord> timeline;
  // Reference check (LoadSessionConfig::check_every): decoded frames compared with the CPU
  // reference render of their pose, PSNR in dB over RGB.
  std::uint64_t checked = 0;
  std::uint64_t check_failures = 0;    // checked frames below LoadSessionConfig::check_min_psnr
  double psnr_min = 0, psnr_mean = 0;  // meaningful only when checked > 0 (JSON: null otherwise)
  StageSums server;                    // after warm-up
  // The camera stopped (LoadSessionConfig::still_s): PSNR (dB, RGB) of the picture shown 1 s and
  // 3 s after the last pose and at the end, against the CPU reference render of the pose it
  // answers (0: no picture by then); the frames and payload bytes received after the last pose.
  double still_psnr_1s = 0, still_psnr_3s = 0, still_psnr_end = 0;
  std::uint64_t still_frames = 0, still_bytes = 0;
};

struct LatencySummary {
  double p50 = 0, p95 = 0, p99 = 0, mean = 0, max = 0;
  std::size_t samples = 0;
};
LatencySummary summarize_latency(const std::vector<double>& latency_ms);

// Totals over sessions: frames, rates, pooled latency percentiles, stage means.
struct RunSummary {
  int sessions = 0;
  int refused = 0;  // sessions the server refused (not counted in fps_min)
  int failed = 0;   // sessions that ran (or tried to) and saw errors
  std::uint64_t frames = 0, poses_sent = 0, bytes = 0, skipped = 0, dropped = 0, stale = 0, errors = 0;
  double fps_total = 0;         // frames / run_seconds, summed over sessions
  double fps_min = 0;           // the slowest session's FPS, among those not refused
  double bytes_per_second = 0;  // summed over sessions
  LatencySummary latency;       // every session's samples pooled
  StageSums server;
};
double session_fps(const SessionResult& s);  // frames / run_seconds (0 when it did not run)
// "ok", "refused" (the server said no to Hello) or "failed" (errors, or no frame at all).
std::string session_status(const SessionResult& s);
RunSummary summarize_run(const std::vector<SessionResult>& sessions);

// A fixed-width table: one row per session (a refused one says so instead of numbers) and a total
// row, then the server stage means.
std::string format_table(const std::vector<SessionResult>& sessions);
// The run as JSON: {"sessions": [...], "total": {...}} with the same numbers as the table.
nlohmann::json run_json(const std::vector<SessionResult>& sessions);

}  // namespace catgs::loadgen
