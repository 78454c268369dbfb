#include "loadgen/load_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace catgs::loadgen {

double percentile(std::vector<double> values, double p) {
  if (!(p >= 0.0 && p <= 100.0))
    throw std::invalid_argument("percentile: p must be in [0, 100], got " + std::to_string(p));
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const double rank = p / 100.0 * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(rank));
  const std::size_t hi = std::min(lo + 1, values.size() - 1);
  return values[lo] + (rank - static_cast<double>(lo)) * (values[hi] - values[lo]);
}

void StageSums::add(const StageSums& o) {
  queue += o.queue;
  lane_wait += o.lane_wait;
  render += o.render;
  convert += o.convert;
  encode += o.encode;
  send += o.send;
  total += o.total;
  frames += o.frames;
  sends += o.sends;
  render_key += o.render_key;
  render_rekey += o.render_rekey;
  window += o.window;
  predicted_gain += o.predicted_gain;
  measured_gain += o.measured_gain;
  predicted_groups += o.predicted_groups;
  measured_groups += o.measured_groups;
  lod_error_px += o.lod_error_px;
  lod_error_px_max = std::max(lod_error_px_max, o.lod_error_px_max);
  splats += o.splats;
  encode_psnr_db += o.encode_psnr_db;
  encode_psnr_frames += o.encode_psnr_frames;
  encode_thread_cpu += o.encode_thread_cpu;
  lane_lod_cpu += o.lane_lod_cpu;
  lane_begin_cpu += o.lane_begin_cpu;
  lane_finish_cpu += o.lane_finish_cpu;
  for (int k = 0; k < 6; ++k) stage[k] += o.stage[k];
  for (const auto& [lane, l] : o.lanes) {
    lanes[lane].frames += l.frames;
    lanes[lane].frame_ms += l.frame_ms;
  }
}

LatencySummary summarize_latency(const std::vector<double>& v) {
  LatencySummary s;
  s.samples = v.size();
  if (v.empty()) return s;
  s.p50 = percentile(v, 50);
  s.p95 = percentile(v, 95);
  s.p99 = percentile(v, 99);
  s.max = *std::max_element(v.begin(), v.end());
  s.mean = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  return s;
}

double session_fps(const SessionResult& s) {
  return s.run_seconds > 0 ? static_cast<double>(s.frames) / s.run_seconds : 0.0;
}

std::string session_status(const SessionResult& s) {
  if (s.refused) return "refused";
  return s.errors > 0 || s.frames == 0 ? "failed" : "ok";
}

RunSummary summarize_run(const std::vector<SessionResult>& sessions) {
  RunSummary t;
  t.sessions = static_cast<int>(sessions.size());
  std::vector<double> pooled;
  bool first_ran = true;
  for (const SessionResult& s : sessions) {
    const std::string status = session_status(s);
    t.refused += status == "refused";
    t.failed += status == "failed";
    t.frames += s.frames;
    t.poses_sent += s.poses_sent;
    t.bytes += s.bytes;
    t.skipped += s.skipped;
    t.dropped += s.dropped;
    t.stale += s.stale;
    t.errors += s.errors;
    const double fps = session_fps(s);
    t.fps_total += fps;
    // A refused session did not run: it has no speed to be the slowest with.
    if (!s.refused) {
      t.fps_min = first_ran ? fps : std::min(t.fps_min, fps);
      first_ran = false;
    }
    if (s.run_seconds > 0) t.bytes_per_second += static_cast<double>(s.bytes) / s.run_seconds;
    pooled.insert(pooled.end(), s.latency_ms.begin(), s.latency_ms.end());
    t.server.add(s.server);
  }
  t.latency = summarize_latency(pooled);
  return t;
}

namespace {

double mean(double sum, std::uint64_t n) { return n ? sum / static_cast<double>(n) : 0.0; }

nlohmann::json latency_json(const LatencySummary& l) {
  return {{"p50_ms", l.p50},   {"p95_ms", l.p95}, {"p99_ms", l.p99},
          {"mean_ms", l.mean}, {"max_ms", l.max}, {"samples", l.samples}};
}

// A mean that was never measured is null, not 0.0 dB.
nlohmann::json measured(double v, std::uint64_t n) { return n ? nlohmann::json(v) : nlohmann::json(nullptr); }

// The renderer's own stage times, means over frames (FrameTimings.stage_*_ms).
nlohmann::json render_stages_json(const StageSums& s) {
  nlohmann::json j = nlohmann::json::object();
  for (int k = 0; k < 6; ++k) j[StageSums::kStageNames[k]] = mean(s.stage[k], s.frames);
  return j;
}

// Per render lane: frames drawn and their mean frame time (the renderer's).
nlohmann::json render_lanes_json(const StageSums& s) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& [lane, l] : s.lanes)
    j.push_back({{"lane", lane}, {"frames", l.frames}, {"frame_ms_mean", mean(l.frame_ms, l.frames)}});
  return j;
}

nlohmann::json stages_json(const StageSums& s) {
  return {
      {"queue_ms", mean(s.queue, s.frames)},
      {"lane_wait_ms", mean(s.lane_wait, s.frames)},
      {"render_ms", mean(s.render, s.frames)},
      {"convert_ms", mean(s.convert, s.frames)},
      {"encode_ms", mean(s.encode, s.frames)},
      {"send_ms", mean(s.send, s.sends)},
      {"total_ms", mean(s.total, s.frames)},
      {"render_key_fraction", s.frames ? static_cast<double>(s.render_key) / static_cast<double>(s.frames) : 0.0},
      {"render_sub_fraction",
       s.frames ? static_cast<double>(s.frames - s.render_key) / static_cast<double>(s.frames) : 0.0},
      {"render_rekey_fraction", s.frames ? static_cast<double>(s.render_rekey) / static_cast<double>(s.frames) : 0.0},
      {"speculation_window_mean", mean(s.window, s.frames)},
      {"speculation_predicted_gain_mean",
       measured(s.predicted_gain / std::max<double>(1, s.predicted_groups), s.predicted_groups)},
      {"speculation_measured_gain_mean",
       measured(s.measured_gain / std::max<double>(1, s.measured_groups), s.measured_groups)},
      {"lod_error_px_mean", mean(s.lod_error_px, s.frames)},
      {"lod_error_px_max", s.lod_error_px_max},
      {"splats_mean", mean(s.splats, s.frames)},
      {"encode_psnr_db_mean", mean(s.encode_psnr_db, s.encode_psnr_frames)},
      {"encode_thread_cpu_ms", mean(s.encode_thread_cpu, s.frames)},
      {"lane_lod_cpu_ms", mean(s.lane_lod_cpu, s.frames)},
      {"lane_begin_cpu_ms", mean(s.lane_begin_cpu, s.frames)},
      {"lane_finish_cpu_ms", mean(s.lane_finish_cpu, s.frames)},
      {"render_stages_ms", render_stages_json(s)},
      {"render_lanes", render_lanes_json(s)},
      {"frames", s.frames}};
}

}  // namespace

nlohmann::json run_json(const std::vector<SessionResult>& sessions) {
  nlohmann::json out;
  out["sessions"] = nlohmann::json::array();
  for (const SessionResult& s : sessions) {
    out["sessions"].push_back(
        {{"index", s.index},
         {"status", session_status(s)},
         {"refusal", s.refusal},
         {"trace", s.trace},
         {"width", s.width},
         {"height", s.height},
         {"session_id", s.session_id},
         {"renderer", s.renderer},
         {"scene", s.scene},
         {"encoder", s.encoder},
         {"pipeline", s.pipeline},
         {"seconds", s.run_seconds},
         {"poses_sent", s.poses_sent},
         {"frames", s.frames},
         {"idr_frames", s.idr_frames},
         {"av1_frames", s.av1_frames},
         {"codec_changes", s.codec_changes},
         {"size_changes", s.size_changes},
         {"min_width", s.min_width},
         {"min_height", s.min_height},
         {"decoded", s.decoded},
         {"fps", session_fps(s)},
         {"bytes", s.bytes},
         {"bytes_per_second", s.run_seconds > 0 ? static_cast<double>(s.bytes) / s.run_seconds : 0.0},
         {"skipped", s.skipped},
         {"dropped", s.dropped},
         {"server_skipped", s.server_skipped},
         {"link_limited_stats", s.link_limited_stats},
         {"link_cap_kbps_min", s.link_cap_kbps_min},
         {"device_memory_mib_max", s.device_memory_mib_max},
         {"memory_fallback_frames", s.memory_fallback_frames},
         {"stream_encoder", s.stream_encoder},
         {"link_kbps_last", s.link_kbps_last},
         {"late_reads", s.late_reads},
         {"receipts_sent", s.receipts_sent},
         {"stale", s.stale},
         {"errors", s.errors},
         {"first_error", s.first_error},
         {"checked", s.checked},
         {"check_failures", s.check_failures},
         {"psnr_min_db", measured(s.psnr_min, s.checked)},
         {"psnr_mean_db", measured(s.psnr_mean, s.checked)},
         {"latency", latency_json(summarize_latency(s.latency_ms))},
         {"server", stages_json(s.server)}});
    if (s.still_frames > 0 || s.still_psnr_end > 0)
      out["sessions"].back()["still"] = {{"psnr_1s_db", s.still_psnr_1s},
                                         {"psnr_3s_db", s.still_psnr_3s},
                                         {"psnr_end_db", s.still_psnr_end},
                                         {"frames", s.still_frames},
                                         {"bytes", s.still_bytes}};
    if (!s.timeline.empty()) {
      nlohmann::json frames = nlohmann::json::array();
      for (const auto& f : s.timeline) frames.push_back({f.t_s, f.latency_ms, f.width, f.height, f.bytes, f.server_ms});
      // [t_s, latency_ms, width, height, bytes, server_ms]
      out["sessions"].back()["timeline"] = std::move(frames);
    }
  }
  const RunSummary t = summarize_run(sessions);
  out["total"] = {{"sessions", t.sessions},
                  {"refused", t.refused},
                  {"failed", t.failed},
                  {"frames", t.frames},
                  {"poses_sent", t.poses_sent},
                  {"fps_total", t.fps_total},
                  {"fps_min", t.fps_min},
                  {"bytes_per_second", t.bytes_per_second},
                  {"skipped", t.skipped},
                  {"dropped", t.dropped},
                  {"stale", t.stale},
                  {"errors", t.errors},
                  {"latency", latency_json(t.latency)},
                  {"server", stages_json(t.server)}};
  return out;
}

std::string format_table(const std::vector<SessionResult>& sessions) {
  std::string out;
  char line[256];
  const auto u = [](std::uint64_t v) { return static_cast<unsigned long long>(v); };
  auto row = [&](const std::string& name, const std::string& size, std::uint64_t frames, double fps,
                 const LatencySummary& l, double kbps, std::uint64_t skipped, std::uint64_t dropped,
                 std::uint64_t stale, std::uint64_t errors) {
    std::snprintf(line, sizeof(line), "%-8s %-18s %7llu %7.1f %8.1f %8.1f %8.1f %9.0f %7llu %7llu %6llu %6llu\n",
                  name.c_str(), size.c_str(), u(frames), fps, l.p50, l.p95, l.p99, kbps, u(skipped), u(dropped),
                  u(stale), u(errors));
    out += line;
  };
  std::snprintf(line, sizeof(line), "%-8s %-18s %7s %7s %8s %8s %8s %9s %7s %7s %6s %6s\n", "session", "size", "frames",
                "FPS", "p50 ms", "p95 ms", "p99 ms", "kbit/s", "skipped", "dropped", "stale", "errors");
  out += line;
  for (const SessionResult& s : sessions) {
    if (s.refused) {
      // No session ran: numbers would read as a session that measured zeros.
      std::snprintf(line, sizeof(line), "%-8s refused by the server: %s\n", std::to_string(s.index).c_str(),
                    s.refusal.c_str());
      out += line;
      continue;
    }
    const double kbps = s.run_seconds > 0 ? 8.0 * static_cast<double>(s.bytes) / s.run_seconds / 1000.0 : 0.0;
    // A stream whose size changed shows its smallest size too (adaptive quality).
    std::string size = std::to_string(s.width) + "x" + std::to_string(s.height);
    if (s.size_changes > 0) size += ">" + std::to_string(s.min_width) + "x" + std::to_string(s.min_height);
    row(std::to_string(s.index), size, s.frames, session_fps(s), summarize_latency(s.latency_ms), kbps, s.skipped,
        s.dropped, s.stale, s.errors);
  }
  const RunSummary t = summarize_run(sessions);
  row("total", "", t.frames, t.fps_total, t.latency, 8.0 * t.bytes_per_second / 1000.0, t.skipped, t.dropped, t.stale,
      t.errors);
  if (t.refused || t.failed) {
    std::snprintf(line, sizeof(line), "sessions: %d ran cleanly, %d refused, %d failed\n",
                  t.sessions - t.refused - t.failed, t.refused, t.failed);
    out += line;
  }
  const StageSums& g = t.server;
  std::snprintf(
      line, sizeof(line),
      "server means (ms): queue %.2f (for a lane %.2f)  render %.2f (key frames %.0f%%, re-keys %.0f%%, W %.2f)  "
      "convert %.2f  encode %.2f  send %.2f  pose->handed %.2f;  slowest session %.1f FPS\n",
      mean(g.queue, g.frames), mean(g.lane_wait, g.frames), mean(g.render, g.frames),
      g.frames ? 100.0 * static_cast<double>(g.render_key) / static_cast<double>(g.frames) : 0.0,
      g.frames ? 100.0 * static_cast<double>(g.render_rekey) / static_cast<double>(g.frames) : 0.0,
      mean(g.window, g.frames), mean(g.convert, g.frames), mean(g.encode, g.frames), mean(g.send, g.sends),
      mean(g.total, g.frames), t.fps_min);
  out += line;
  if (g.lod_error_px_max > 0) {
    std::snprintf(line, sizeof(line), "level of detail: bound %.2f px mean, %.2f px max; %.2f M Gaussians a frame\n",
                  mean(g.lod_error_px, g.frames), g.lod_error_px_max, mean(g.splats, g.frames) / 1e6);
    out += line;
  }
  if (g.encode_psnr_frames > 0) {
    // The codec's loss, as the encoder measured it: the host's picture, and its worst session's.
    double worst = 1e9;
    std::string worst_encoder;
    for (const SessionResult& s : sessions)
      if (s.server.encode_psnr_frames > 0 && mean(s.server.encode_psnr_db, s.server.encode_psnr_frames) < worst) {
        worst = mean(s.server.encode_psnr_db, s.server.encode_psnr_frames);
        worst_encoder = s.stream_encoder;
      }
    std::snprintf(line, sizeof(line),
                  "encoder picture: %.2f dB mean; the lowest session %.2f dB (%s); the encode call's own thread "
                  "%.2f ms of CPU a frame\n",
                  mean(g.encode_psnr_db, g.encode_psnr_frames), worst, worst_encoder.c_str(),
                  mean(g.encode_thread_cpu, g.frames));
    out += line;
  }
  if (g.frames > 0) {
    std::snprintf(line, sizeof(line),
                  "render lane CPU a frame: %.3f ms choosing the LOD bound, %.3f beginning, %.3f finishing\n",
                  mean(g.lane_lod_cpu, g.frames), mean(g.lane_begin_cpu, g.frames), mean(g.lane_finish_cpu, g.frames));
    out += line;
  }
  for (const SessionResult& s : sessions)
    if (s.checked > 0) {
      std::snprintf(line, sizeof(line),
                    "session %d reference check: %llu frames, PSNR min %.1f dB, mean %.1f dB, %llu "
                    "below the bar\n",
                    s.index, static_cast<unsigned long long>(s.checked), s.psnr_min, s.psnr_mean,
                    static_cast<unsigned long long>(s.check_failures));
      out += line;
    }
  for (const SessionResult& s : sessions)
    if (!s.refused && !s.first_error.empty())
      out += "session " + std::to_string(s.index) + " error: " + s.first_error + "\n";
  return out;
}

}  // namespace catgs::loadgen
