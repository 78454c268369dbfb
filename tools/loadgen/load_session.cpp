#include "common/image_io.h"
#include "loadgen/load_session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "cpu/cpu_renderer.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "loadgen/h264_decoder.h"
#include "loadgen/stream_client.h"

namespace catgs::loadgen {

namespace {

using Clock = std::chrono::steady_clock;

double now_ms() {
  return std::chrono::duration<double, std::milli>(Clock::now().time_since_epoch()).count();
}

glm::vec3 to_vec3(const pb::Vec3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

constexpr double kTraceRateHz = 120.0;
constexpr double kSecondsPerView = 0.5;

}  // namespace

Trace make_load_trace(const std::string& spec, const GaussianModel* scene, const pb::Welcome& welcome,
                      int width, int height) {
  if (spec == "orbit") {
    Bounds b;
    b.min = to_vec3(welcome.scene_bounds().min());
    b.max = to_vec3(welcome.scene_bounds().max());
    if (scene) b = robust_bounds(*scene);
    const float radius = glm::length(to_vec3(welcome.initial_pose().position()) - b.center());
    GeneratorParams g;
    g.duration_s = 10.0;
    g.rate_hz = kTraceRateHz;
    g.width = width;
    g.height = height;
    g.fov_deg = static_cast<float>(welcome.initial_pose().vertical_fov_deg());
    if (scene) g.up = estimate_up(*scene);
    return make_orbit(b, radius, 0.3f * radius, 360.0f, g);
  }
  if (spec.rfind("real:", 0) == 0) {
    if (!scene) throw std::invalid_argument("trace " + spec + " needs --scene (the path is fitted onto it)");
    return fit_trace_to_scene(load_inria_cameras(spec.substr(5)), *scene, estimate_up(*scene), 0.6f,
                              kTraceRateHz, kSecondsPerView, width, height);
  }
  if (spec.rfind("cameras:", 0) == 0)
    return interpolate_views(load_inria_cameras(spec.substr(8), width, height), kTraceRateHz,
                             kSecondsPerView);
  Trace t = read_trace(spec);
  for (auto& tc : t) tc.camera = tc.camera.rescaled(width, height);
  return t;
}

const Camera& camera_at(const Trace& trace, double t_s) {
  const double start = trace.front().time_s;
  const double duration = trace.back().time_s - start;
  double t = start;
  if (duration > 0) t += std::fmod(std::max(0.0, t_s), duration);
  // The last sample at or before t.
  auto it = std::upper_bound(trace.begin(), trace.end(), t,
                             [](double x, const TimedCamera& c) { return x < c.time_s; });
  return (it == trace.begin() ? trace.front() : *(it - 1)).camera;
}

SessionResult run_load_session(const LoadSessionConfig& cfg) {
  SessionResult r;
  r.index = cfg.index;
  r.trace = cfg.trace;
  auto note_error = [&r](const std::string& what) {
    r.errors++;
    if (r.first_error.empty()) r.first_error = what;
  };
  const bool check = cfg.check_every > 0;
  if (check && !cfg.scene)
    throw std::invalid_argument("loadgen: the reference check needs the scene (--scene)");
  try {
    StreamClient client;
    client.connect(cfg.port, cfg.host);
    const pb::Welcome welcome = client.hello(cfg.width, cfg.height, cfg.token);
    r.width = static_cast<int>(welcome.width());
    r.height = static_cast<int>(welcome.height());
    r.session_id = welcome.session_id();
    r.renderer = welcome.renderer();
    r.encoder = welcome.encoder();
    r.pipeline = welcome.pipeline();
    const Trace trace = make_load_trace(cfg.trace, cfg.scene.get(), welcome, r.width, r.height);
    if (trace.empty()) throw std::runtime_error("empty trace " + cfg.trace);

    H264Decoder decoder;
    std::vector<std::uint8_t> rgba;
    std::vector<double> sent_at;  // client time each pose was sent, by sequence
    std::vector<pb::Pose> sent_poses;  // reference check: each pose as sent, by sequence
    std::unique_ptr<cpu::CpuRenderer> reference;
    if (check) reference = std::make_unique<cpu::CpuRenderer>(cfg.scene, RenderOptions{});
    double psnr_sum = 0;
    std::int64_t newest_answered = -1;
    std::uint64_t answered = 0;   // distinct poses that got a frame
    int outstanding = 0;
    const auto t0 = Clock::now();
    const auto send_end = t0 + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(cfg.seconds));
    auto send_pose = [&] {
      const double t_s = std::chrono::duration<double>(Clock::now() - t0).count() + cfg.offset_s;
      const auto seq = static_cast<std::uint32_t>(sent_at.size());
      sent_at.push_back(now_ms());
      const pb::Pose pose = pose_from_camera(camera_at(trace, t_s), seq, sent_at.back());
      if (check) sent_poses.push_back(pose);
      client.send_pose(pose);
      r.poses_sent++;
    };
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(cfg.rate_hz > 0 ? 1.0 / cfg.rate_hz : 0.0));
    auto next_pose_at = t0;
    auto drain_end = send_end + std::chrono::duration_cast<Clock::duration>(
                                    std::chrono::duration<double, std::milli>(cfg.drain_ms));
    for (;;) {
      const auto now = Clock::now();
      const bool sending = now < send_end;
      if (!sending && (now >= drain_end || newest_answered + 1 == static_cast<std::int64_t>(sent_at.size())))
        break;
      if (sending && cfg.rate_hz > 0) {
        if (now >= next_pose_at) {
          send_pose();
          // A client that fell behind (a slow decode) skips the missed slots, not bursts them.
          next_pose_at = std::max(next_pose_at + period, now);
        }
      } else if (sending) {
        while (outstanding < cfg.depth) {
          send_pose();
          outstanding++;
        }
      }
      int wait_ms = 20;
      if (sending && cfg.rate_hz > 0)
        wait_ms = static_cast<int>(std::clamp<long long>(
            std::chrono::duration_cast<std::chrono::milliseconds>(next_pose_at - Clock::now()).count(), 0, 20));
      auto msg = client.recv(wait_ms);
      if (!msg) continue;
      if (msg->has_error()) {
        note_error("server Error " + pb::ErrorCode_Name(msg->error().code()) + ": " + msg->error().reason());
        break;
      }
      if (!msg->has_frame()) continue;
      const pb::Frame& f = msg->frame();
      r.frames++;
      r.bytes += f.payload().size();
      if (f.key_frame()) r.idr_frames++;
      if (outstanding > 0) outstanding--;
      if (cfg.decode || check) {
        int w = 0, h = 0;
        try {
          const bool got = decoder.decode(f.payload(), rgba, w, h);
          if (got) r.decoded++;
          if (w != r.width || h != r.height) note_error("frame decoded to " + std::to_string(w) + "x" + std::to_string(h));
          if (got && check && r.frames % static_cast<std::uint64_t>(cfg.check_every) == 0 &&
              f.pose_sequence() < sent_poses.size()) {
            Image decoded_image, want;
            decoded_image.width = w;
            decoded_image.height = h;
            decoded_image.rgba8 = rgba;
            reference->render(camera_from_pose(sent_poses[f.pose_sequence()], w, h), want);
            const double psnr = psnr_rgba8(decoded_image, want);
            r.psnr_min = r.checked == 0 ? psnr : std::min(r.psnr_min, psnr);
            psnr_sum += psnr;
            r.checked++;
            r.psnr_mean = psnr_sum / static_cast<double>(r.checked);
            if (!(psnr >= cfg.check_min_psnr)) r.check_failures++;
          }
        } catch (const std::exception& e) {
          note_error(std::string("decode: ") + e.what());
        }
      }
      const double latency = now_ms() - f.client_time_ms();
      const auto seq = static_cast<std::int64_t>(f.pose_sequence());
      if (seq >= static_cast<std::int64_t>(sent_at.size())) {
        note_error("frame for a pose never sent (" + std::to_string(seq) + ")");
        continue;
      }
      if (seq <= newest_answered || latency > cfg.stale_ms) r.stale++;
      if (seq > newest_answered) {
        newest_answered = seq;
        answered++;
      }
      if (r.frames <= static_cast<std::uint64_t>(cfg.warmup_frames)) continue;
      r.latency_ms.push_back(latency);
      const pb::FrameTimings& t = f.timings();
      r.server.queue += t.queue_ms();
      r.server.render += t.render_ms();
      r.server.convert += t.convert_ms();
      r.server.encode += t.encode_ms();
      r.server.total += t.total_ms();
      r.server.frames++;
      if (t.previous_send_ms() > 0) {
        r.server.send += t.previous_send_ms();
        r.server.sends++;
      }
      if (t.render_key_frame()) r.server.render_key++;
    }
    r.run_seconds = std::chrono::duration<double>(std::min(Clock::now(), send_end) - t0).count();
    r.dropped = r.poses_sent - answered;
    client.ws().close();
  } catch (const std::exception& e) {
    note_error(e.what());
  }
  return r;
}

}  // namespace catgs::loadgen
