#include "common/image_io.h"
#include "loadgen/load_session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <stdexcept>
#include <thread>

#include <glm/gtc/constants.hpp>

#include "cpu/cpu_renderer.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "loadgen/video_decoder.h"
#include "loadgen/stream_client.h"
#include "proto/message_validation.h"

namespace catgs::loadgen {

namespace {

using Clock = std::chrono::steady_clock;

double now_ms() { return std::chrono::duration<double, std::milli>(Clock::now().time_since_epoch()).count(); }

glm::vec3 to_vec3(const pb::Vec3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

glm::quat to_quat(const pb::Quat& q) {
  return {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z())};
}

constexpr double kTraceRateHz = 120.0;
constexpr double kSecondsPerView = 0.5;

}  // namespace

Trace make_load_trace(const std::string& spec, const GaussianModel* scene, const pb::Welcome& welcome, int width,
                      int height) {
  if (spec == "orbit") {
    Bounds b;
    b.min = to_vec3(welcome.scene_bounds().min());
    b.max = to_vec3(welcome.scene_bounds().max());
    if (scene) b = robust_bounds(*scene);
    GeneratorParams g;
    g.duration_s = 10.0;
    g.rate_hz = kTraceRateHz;
    g.width = width;
    g.height = height;
    g.fov_deg = static_cast<float>(welcome.initial_pose().vertical_fov_deg());
    if (scene) g.up = estimate_up(*scene);
    if (welcome.scene_scale() > 0) {  // the viewer's orbit: about the server's orbit centre and up
      const glm::vec3 centre = to_vec3(welcome.orbit_centre());
      b.min = b.max = centre;
      g.up = to_vec3(welcome.up());
    }
    const float radius = glm::length(to_vec3(welcome.initial_pose().position()) - b.center());
    return make_orbit(b, radius, 0.3f * radius, 360.0f, g);
  }
  if (spec.rfind("real:", 0) == 0) {
    if (!scene) throw std::invalid_argument("trace " + spec + " needs --scene (the path is fitted onto it)");
    return fit_trace_to_scene(load_inria_cameras(spec.substr(5)), *scene, estimate_up(*scene), 0.6f, kTraceRateHz,
                              kSecondsPerView, width, height);
  }
  if (spec.rfind("cameras:", 0) == 0)
    return interpolate_views(load_inria_cameras(spec.substr(8), width, height), kTraceRateHz, kSecondsPerView);
  Trace t = read_trace(spec);
  for (auto& tc : t) tc.camera = tc.camera.rescaled(width, height);
  return t;
}

PageOrbit page_orbit(const pb::Welcome& welcome) {
  const glm::dvec3 position = to_vec3(welcome.initial_pose().position());
  const glm::dvec3 forward = glm::dquat(to_quat(welcome.initial_pose().orientation())) * glm::dvec3(0, 0, 1);
  glm::dvec3 target;
  double scale = welcome.scene_scale();
  if (scale > 0) {  // the orbit the server sends
    target = to_vec3(welcome.orbit_centre());
  } else {  // the bounds' centre, else a point ahead
    const glm::dvec3 lo = to_vec3(welcome.scene_bounds().min()), hi = to_vec3(welcome.scene_bounds().max());
    scale = glm::length(hi - lo);
    target = 0.5 * (lo + hi);
    if (!(scale > 0) || glm::length(target - position) < 1e-6)
      target = position + forward * (scale > 0 ? scale / 2 : 1.0);
    if (!(scale > 0)) scale = 2 * glm::length(target - position);
  }
  return {std::max(glm::length(target - position), scale * 1e-3), scale};
}

Camera left_eye_view(const Camera& head, const HeadsetOptics& optics) {
  const glm::quat q = head.orientation();
  const glm::vec3 at = head.position() - 0.5f * optics.ipd * (glm::mat3_cast(q)[0]);
  return Camera::from_pose(at, q, glm::degrees(optics.angle_up - optics.angle_down), head.width, head.height);
}

Camera turned_head(const Camera& trace_camera, double t_s, const HeadTurn& turn) {
  const double yaw = glm::radians(turn.amplitude_deg) * std::sin(2.0 * glm::pi<double>() * t_s / turn.period_s);
  // About the camera's own y axis (down in OpenCV axes: the head's up, sign aside).
  const glm::quat q = trace_camera.orientation() * glm::angleAxis(static_cast<float>(yaw), glm::vec3(0, 1, 0));
  return Camera::from_pose(trace_camera.position(), q, trace_camera.vertical_fov_deg(), trace_camera.width,
                           trace_camera.height);
}

const Camera& camera_at(const Trace& trace, double t_s) {
  const double start = trace.front().time_s;
  const double duration = trace.back().time_s - start;
  double t = start;
  if (duration > 0) t += std::fmod(std::max(0.0, t_s), duration);
  // The last sample at or before t.
  auto it =
      std::upper_bound(trace.begin(), trace.end(), t, [](double x, const TimedCamera& c) { return x < c.time_s; });
  return (it == trace.begin() ? trace.front() : *(it - 1)).camera;
}

namespace {

void note_error(SessionResult& r, const std::string& what) {
  r.errors++;
  if (r.first_error.empty()) r.first_error = what;
}

// Connects and says Hello; the Welcome's size and names go into `r`.
pb::Welcome open_session(const LoadSessionConfig& cfg, StreamClient& client, SessionResult& r) {
  client.ws().use_tls(cfg.tls);
  client.connect(cfg.port, cfg.host);
  const pb::Welcome welcome =
      client.hello(cfg.width, cfg.height, cfg.token, 10000, cfg.scene_name, nullptr, false, cfg.offer_av1);
  r.width = static_cast<int>(welcome.width());
  r.height = static_cast<int>(welcome.height());
  r.session_id = welcome.session_id();
  r.renderer = welcome.renderer();
  r.encoder = welcome.encoder();
  r.pipeline = welcome.pipeline();
  r.scene = welcome.scene_name();
  return welcome;
}

// An open session from its first pose to its close: sends poses on the trace's clock, takes
// the frames and measures them into `r`. Runs on the session's thread; throws what the client
// and the decoder's set-up throw.
class PoseLoop {
 public:
  PoseLoop(const LoadSessionConfig& cfg, SessionResult& r, StreamClient& client, Trace trace,
           const pb::Welcome& welcome)
      : cfg_(cfg), r_(r), client_(client), trace_(std::move(trace)), check_(cfg.check_every > 0) {
    if (!cfg.record_dir.empty()) start_recording(welcome);
    if (cfg.link.rate_mbit > 0) {  // the stream under the emulated link's rate
      pb::ClientMessage m;
      m.mutable_quality()->set_max_bitrate_kbps(
          static_cast<std::uint32_t>(std::clamp(kLinkRateShare * 1000.0 * cfg.link.rate_mbit, 100.0, 100000.0)));
      client_.send(m);
    }
    if (check_ || cfg.still_s > 0)
      reference_ =
          std::make_unique<cpu::CpuRenderer>(cfg.reference_scene ? cfg.reference_scene : cfg.scene, RenderOptions{});
    // The clock starts once everything is ready: set-up is not sending time.
    t0_ = Clock::now();
    send_end_ = t0_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(cfg.seconds));
    const double drain_ms = cfg.still_s > 0 ? 1000.0 * cfg.still_s : cfg.drain_ms;
    drain_end_ =
        send_end_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(drain_ms));
    if (cfg.read_stall_max_ms > 0)
      stall_ms_ = std::uniform_int_distribution<int>(cfg.read_stall_min_ms, cfg.read_stall_max_ms);
    period_ = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(cfg.rate_hz > 0 ? 1.0 / cfg.rate_hz : 0.0));
    next_pose_at_ = t0_;
  }

  // Until the sending time is over and the last pose is answered (or drain_ms passed; with
  // still_s, until still_s passed), or the server sends an Error. Closes the connection.
  void run() {
    Progress* progress = cfg_.progress;
    const bool stalls = cfg_.read_stall_max_ms > 0;
    for (;;) {
      const auto now = Clock::now();
      const bool sending = now < send_end_;
      const bool still = cfg_.still_s > 0;
      if (!sending && (now >= drain_end_ || (!still && newest_answered_ + 1 == sent()))) break;
      if (sending) send_due_poses(now);
      if (still && !sending) take_still_marks(now);
      // Away from the socket for longer than kLateReadMs (a stall, a slow decode): what it reads
      // now may have waited, and its receipts would say so as if the link had queued it.
      if (Clock::now() - last_read_end_ > kLateReadMs) late_read_ = true;
      // A busy client reads what has arrived, then is away for a while (its thread busy).
      auto msg = client_.recv(stalls ? 0 : wait_ms(sending));
      last_read_end_ = Clock::now();
      if (!msg) {
        late_read_ = false;  // caught up: nothing was waiting
        if (stalls) std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms_(random_)));
        continue;
      }
      if (msg->has_error()) {
        note_error(r_, "server Error " + pb::ErrorCode_Name(msg->error().code()) + ": " + msg->error().reason());
        break;
      }
      if (msg->has_frame()) {
        on_frame(msg->frame());
        if (progress) progress->frames++;
      }
      if (msg->has_stats()) on_stats(msg->stats());
    }
    if (cfg_.still_s > 0 && r_.still_psnr_end == 0 && have_shown_) r_.still_psnr_end = shown_psnr();
    r_.run_seconds = std::chrono::duration<double>(std::min(Clock::now(), send_end_) - t0_).count();
    // Poses up to the newest answered one that got no frame were replaced by a newer pose (latest
    // wins); those after it were never answered at all.
    const auto reached = static_cast<std::uint64_t>(newest_answered_ + 1);
    r_.skipped = reached - answered_;
    r_.dropped = r_.poses_sent - reached;
    client_.ws().close();
    if (recording_) write_recording(*recording_, cfg_.record_dir);
  }

 private:
  std::int64_t sent() const { return static_cast<std::int64_t>(sent_at_.size()); }

  void send_due_poses(Clock::time_point now) {
    if (cfg_.rate_hz > 0) {
      if (now < next_pose_at_) return;
      send_pose();
      // A client that fell behind (a slow decode) skips the missed slots, not bursts them.
      next_pose_at_ = std::max(next_pose_at_ + period_, now);
      return;
    }
    while (outstanding_ < cfg_.depth) {
      send_pose();
      outstanding_++;
    }
  }

  // The session's recording (recording.h): its settings and trace now, poses and frames as they go.
  void start_recording(const pb::Welcome& welcome) {
    recording_ = std::make_unique<SessionRecording>();
    SessionRecording& rec = *recording_;
    rec.width = r_.width;
    rec.height = r_.height;
    rec.trace_spec = cfg_.trace;
    rec.offset_s = cfg_.offset_s;
    rec.seconds = cfg_.seconds;
    rec.link = cfg_.link;
    const PageOrbit orbit = page_orbit(welcome);
    rec.plane_distance = orbit.distance;
    rec.scene_scale = orbit.scene_scale;
    rec.trace = trace_;
  }

  double since_start_ms() const { return std::chrono::duration<double, std::milli>(Clock::now() - t0_).count(); }

  void send_pose() {
    // The emulated link holds a pose for half the round trip: the server gets, now, where the
    // visitor was that long ago.
    const double t_s = (since_start_ms() - 0.5 * cfg_.link.rtt_ms) / 1000.0 + cfg_.offset_s;
    const auto seq = static_cast<std::uint32_t>(sent_at_.size());
    if (recording_) recording_->poses.push_back({seq, since_start_ms(), t_s});
    sent_at_.push_back(now_ms());
    // On the visitor's clock: it was at this pose half the round trip ago.
    const double client_ms = sent_at_.back() - 0.5 * cfg_.link.rtt_ms;
    pb::Pose pose =
        cfg_.stereo && cfg_.mono_eye
            ? pose_from_camera(left_eye_view(turned_head(camera_at(trace_, t_s), t_s), cfg_.optics), seq, client_ms)
        : cfg_.stereo ? stereo_pose_from_camera(turned_head(camera_at(trace_, t_s), t_s), cfg_.optics, seq, client_ms)
                      : pose_from_camera(camera_at(trace_, t_s), seq, client_ms);
    if (cfg_.stereo) pose.set_display_hz(cfg_.rate_hz);  // a headset's display rate: the stream's
    // As the web viewer does: the newest frame's latency rides on the next pose to /metrics.
    pose.set_shown_latency_ms(unreported_latency_ms_);
    unreported_latency_ms_ = 0;
    // And the newest frame's receipt, for the server's rate controller (link_rate.h).
    if (receipt_.arrived_ms > 0) {
      pose.set_received_frame_sequence(receipt_.sequence);
      pose.set_received_ms(receipt_.arrived_ms);
      receipt_ = {};
      r_.receipts_sent++;
    }
    if (reference_) sent_poses_.push_back(pose);
    client_.send_pose(pose);
    r_.poses_sent++;
    if (cfg_.progress) cfg_.progress->poses++;
  }

  // How long recv() may wait: until the next paced pose is due (rounded up: a wait that ends short
  // of it spins through the rest with recv(0)), at most 20 ms.
  int wait_ms(bool sending) const {
    if (!(sending && cfg_.rate_hz > 0)) return 20;
    return static_cast<int>(std::clamp<long long>(
        std::chrono::ceil<std::chrono::milliseconds>(next_pose_at_ - Clock::now()).count(), 0, 20));
  }

  void on_stats(const pb::Stats& s) {
    r_.server_skipped = s.poses_skipped();
    r_.device_memory_mib_max = std::max(r_.device_memory_mib_max, s.device_memory_mib());
    r_.memory_fallback_frames += s.memory_fallback_frames();
    if (!s.encoder().empty()) r_.stream_encoder = s.encoder();
    if (s.link_kbps() > 0) r_.link_kbps_last = s.link_kbps();
    if (s.bitrate_cap_kbps() == 0) return;  // the link does not limit the stream
    r_.link_limited_stats++;
    r_.link_cap_kbps_min =
        r_.link_cap_kbps_min ? std::min(r_.link_cap_kbps_min, s.bitrate_cap_kbps()) : s.bitrate_cap_kbps();
  }

  void on_frame(const pb::Frame& f) {
    const double arrived_ms = now_ms();  // before the decode: the receipt is the network's
    if (recording_) record_frame(f);
    r_.frames++;
    if (f.width() > 0 &&
        (static_cast<int>(f.width()) != frame_width_ || static_cast<int>(f.height()) != frame_height_)) {
      if (frame_width_ > 0) r_.size_changes++;
      frame_width_ = static_cast<int>(f.width());
      frame_height_ = static_cast<int>(f.height());
      const std::int64_t pixels = static_cast<std::int64_t>(frame_width_) * frame_height_;
      if (r_.min_width == 0 || pixels < static_cast<std::int64_t>(r_.min_width) * r_.min_height) {
        r_.min_width = frame_width_;
        r_.min_height = frame_height_;
      }
    }
    r_.bytes += f.payload().size();
    if (f.key_frame()) r_.idr_frames++;
    const bool av1 = f.codec() == pb::CODEC_AV1;
    if (av1) r_.av1_frames++;
    if (r_.frames > 1 && av1 != last_av1_) r_.codec_changes++;
    last_av1_ = av1;
    if (outstanding_ > 0) outstanding_--;
    if (Clock::now() >= send_end_) {
      r_.still_frames++;
      r_.still_bytes += f.payload().size();
    }
    if (cfg_.decode || reference_) decode_and_check(f);
    // Pose to frame as the visitor sees it: the emulated link's frame half comes on top.
    const double latency = now_ms() + 0.5 * cfg_.link.rtt_ms - f.client_time_ms();
    unreported_latency_ms_ = std::clamp(latency, 0.0, server::kMaxShownLatencyMs);
    // A receipt says when the frame arrived; one read after the client was away says when the
    // client came back (the page does the same: web_client/app.js).
    if (late_read_) r_.late_reads++;
    if (cfg_.receipts && (!late_read_ || cfg_.late_receipts)) receipt_ = {f.sequence(), arrived_ms};
    if (cfg_.timeline && !sent_at_.empty())
      r_.timeline.push_back({(now_ms() - sent_at_.front()) / 1000.0, latency, static_cast<int>(f.width()),
                             static_cast<int>(f.height()), f.payload().size(), f.timings().total_ms()});
    const auto seq = static_cast<std::int64_t>(f.pose_sequence());
    if (seq >= sent()) {
      note_error(r_, "frame for a pose never sent (" + std::to_string(seq) + ")");
      return;
    }
    if (seq <= newest_answered_ || latency > cfg_.stale_ms) r_.stale++;
    if (seq > newest_answered_) {
      newest_answered_ = seq;
      answered_++;
    }
    if (r_.frames <= static_cast<std::uint64_t>(cfg_.warmup_frames)) return;
    if (cfg_.warmup_s > 0 && f.client_time_ms() - sent_at_.front() < 1000.0 * cfg_.warmup_s) return;
    r_.latency_ms.push_back(latency);
    add_server_timings(f.timings());
  }

  void record_frame(const pb::Frame& f) {
    if (f.codec() == pb::CODEC_AV1) {
      note_error(r_, "--record: an AV1 frame (the recording holds H.264 only)");
      return;
    }
    SessionRecording& rec = *recording_;
    RecordedFrame k;
    k.sequence = f.sequence();
    k.pose_sequence = f.pose_sequence();
    k.arrived_ms = since_start_ms();
    k.key = f.key_frame();
    k.width = static_cast<int>(f.width());
    k.height = static_cast<int>(f.height());
    k.lod_error_px = f.timings().lod_error_px();
    if (f.has_shown_pose()) {
      const pb::Pose& p = f.shown_pose();
      k.shown_pose = {p.position().x(),    p.position().y(),    p.position().z(),    p.orientation().w(),
                      p.orientation().x(), p.orientation().y(), p.orientation().z(), p.vertical_fov_deg()};
    }
    if (f.has_depth_grid()) k.depth_grid = f.depth_grid();
    k.offset = rec.stream.size();
    k.bytes = f.payload().size();
    rec.stream += f.payload();
    rec.frames.push_back(k);
  }

  void decode_and_check(const pb::Frame& f) {
    int w = 0, h = 0;
    try {
      // The codec changes only on a key frame (Frame.codec): a decoder of the new one from there.
      const std::string codec = f.codec() == pb::CODEC_AV1 ? "av1" : "h264";
      if (!decoder_ || decoder_->codec() != codec) decoder_ = std::make_unique<VideoDecoder>(codec);
      const bool got = decoder_->decode(f.payload(), rgba_, w, h);
      if (got) {
        r_.decoded++;
        shown_bound_px_ = f.timings().lod_error_px();
        have_shown_ = f.pose_sequence() < sent_poses_.size();
        // The pose the picture shows: the server's prediction where it made one
        // (Frame.shown_pose), else the Pose it answers.
        if (have_shown_) shown_pose_ = f.has_shown_pose() ? f.shown_pose() : sent_poses_[f.pose_sequence()];
      }
      // The server may change the size (adaptive quality: a slow host or link); every frame
      // says its size, and the picture must have it.
      if (got && (w != static_cast<int>(f.width()) || h != static_cast<int>(f.height())))
        note_error(r_, "frame decoded to " + std::to_string(w) + "x" + std::to_string(h) + ", the Frame says " +
                           std::to_string(f.width()) + "x" + std::to_string(f.height()));
      if (got && check_ && r_.frames % static_cast<std::uint64_t>(cfg_.check_every) == 0 &&
          f.pose_sequence() < sent_poses_.size())
        check_against_reference(shown_pose_, f.timings().lod_error_px(), w, h);
    } catch (const std::exception& e) {
      note_error(r_, std::string("decode: ") + e.what());
    }
  }

  // The decoded picture (rgba_, w x h) against the CPU reference render of the pose it shows,
  // at the LOD bound the server drew it at (`bound_px`, frame pixels; drawn only where the
  // reference scene has its level of detail: LoadSessionConfig::reference_scene).
  double reference_psnr(const pb::Pose& pose, float bound_px, int w, int h) {
    if (reference_->options().lod_error_px != bound_px) {
      RenderOptions o = reference_->options();
      o.lod_error_px = bound_px;
      reference_->set_options(o);
    }
    Image decoded_image, want;
    decoded_image.width = w;
    decoded_image.height = h;
    decoded_image.rgba8 = rgba_;
    reference_->render(camera_from_pose(pose, w, h), want);
    return psnr_rgba8(decoded_image, want);
  }

  void check_against_reference(const pb::Pose& pose, float bound_px, int w, int h) {
    const double psnr = reference_psnr(pose, bound_px, w, h);
    r_.psnr_min = r_.checked == 0 ? psnr : std::min(r_.psnr_min, psnr);
    psnr_sum_ += psnr;
    r_.checked++;
    r_.psnr_mean = psnr_sum_ / static_cast<double>(r_.checked);
    if (!(psnr >= cfg_.check_min_psnr)) r_.check_failures++;
  }

  // The picture shown now (the newest decoded) against the reference of its pose.
  double shown_psnr() {
    const int w = frame_width_, h = frame_height_;
    if (rgba_.size() != static_cast<std::size_t>(w) * h * 4) return 0;
    return reference_psnr(shown_pose_, shown_bound_px_, w, h);
  }

  // The camera stopped at send_end_: the picture shown 1 s and 3 s later.
  void take_still_marks(Clock::time_point now) {
    if (!have_shown_) return;
    if (r_.still_psnr_1s == 0 && now >= send_end_ + std::chrono::seconds(1)) r_.still_psnr_1s = shown_psnr();
    if (r_.still_psnr_3s == 0 && now >= send_end_ + std::chrono::seconds(3)) r_.still_psnr_3s = shown_psnr();
  }

  void add_server_timings(const pb::FrameTimings& t) {
    r_.server.queue += t.queue_ms();
    r_.server.lane_wait += t.lane_wait_ms();
    r_.server.render += t.render_ms();
    r_.server.convert += t.convert_ms();
    r_.server.encode += t.encode_ms();
    r_.server.total += t.total_ms();
    r_.server.frames++;
    const double stages[6] = {t.stage_frame_ms(), t.stage_preprocess_ms(), t.stage_keys_ms(),
                              t.stage_sort_ms(),  t.stage_ranges_ms(),     t.stage_rasterize_ms()};
    for (int k = 0; k < 6; ++k) r_.server.stage[k] += stages[k];
    StageSums::Lane& lane = r_.server.lanes[static_cast<int>(t.render_lane())];
    lane.frames++;
    lane.frame_ms += t.stage_frame_ms();
    if (t.previous_send_ms() > 0) {
      r_.server.send += t.previous_send_ms();
      r_.server.sends++;
    }
    if (t.render_key_frame()) r_.server.render_key++;
    if (t.render_rekey()) r_.server.render_rekey++;
    r_.server.window += t.speculation_window();
    if (t.speculation_predicted_gain() > 0) {
      r_.server.predicted_gain += t.speculation_predicted_gain();
      r_.server.predicted_groups++;
    }
    if (t.speculation_measured_gain() > 0) {
      r_.server.measured_gain += t.speculation_measured_gain();
      r_.server.measured_groups++;
    }
    r_.server.lod_error_px += t.lod_error_px();
    r_.server.lod_error_px_max = std::max<double>(r_.server.lod_error_px_max, t.lod_error_px());
    r_.server.splats += t.splats();
    r_.server.encode_thread_cpu += t.encode_thread_cpu_ms();
    r_.server.lane_lod_cpu += t.lane_lod_cpu_ms();
    r_.server.lane_begin_cpu += t.lane_begin_cpu_ms();
    r_.server.lane_finish_cpu += t.lane_finish_cpu_ms();
    if (t.encode_psnr_db() > 0) {
      r_.server.encode_psnr_db += t.encode_psnr_db();
      r_.server.encode_psnr_frames++;
    }
  }

  const LoadSessionConfig& cfg_;
  SessionResult& r_;
  StreamClient& client_;
  const Trace trace_;
  const bool check_;
  std::unique_ptr<SessionRecording> recording_;  // --record
  std::unique_ptr<VideoDecoder> decoder_;        // of the last frame's codec, made by its first frame
  bool last_av1_ = false;                        // the last Frame's codec was AV1
  int frame_width_ = 0, frame_height_ = 0;       // the size of the last Frame
  std::vector<std::uint8_t> rgba_;
  std::vector<double> sent_at_;                  // client time each pose was sent, by sequence
  std::vector<pb::Pose> sent_poses_;             // reference check: each pose as sent, by sequence
  std::unique_ptr<cpu::CpuRenderer> reference_;  // reference checks and the still picture's
  pb::Pose shown_pose_;                          // the pose the newest decoded picture shows
  float shown_bound_px_ = 0;                     // and the LOD bound it was drawn at
  bool have_shown_ = false;
  // Away from the socket longer than this: the frames read next arrived earlier than read.
  static constexpr std::chrono::milliseconds kLateReadMs{50};
  Clock::time_point last_read_end_ = Clock::now();
  bool late_read_ = false;  // since the client came back from being away, nothing read was waiting
  std::mt19937 random_{std::random_device{}()};
  std::uniform_int_distribution<int> stall_ms_{0, 0};  // --read-stall-ms
  double psnr_sum_ = 0;
  double unreported_latency_ms_ = 0;  // the newest frame's latency, for the next Pose
  struct Receipt {
    std::uint32_t sequence = 0;
    double arrived_ms = 0;  // 0: none to send
  } receipt_;               // the newest frame's arrival, for the next Pose
  std::int64_t newest_answered_ = -1;
  std::uint64_t answered_ = 0;  // distinct poses that got a frame
  int outstanding_ = 0;         // closed loop: poses not yet answered
  Clock::time_point t0_, send_end_, drain_end_, next_pose_at_;
  Clock::duration period_{};
};

}  // namespace

SessionResult run_load_session(const LoadSessionConfig& cfg) {
  SessionResult r;
  r.index = cfg.index;
  r.trace = cfg.trace;
  if (cfg.check_every > 0 && !cfg.scene)
    throw std::invalid_argument("loadgen: the reference check needs the scene (--scene)");
  Progress* progress = cfg.progress;
  bool open = false;
  if (cfg.arrive_after_s > 0) std::this_thread::sleep_for(std::chrono::duration<double>(cfg.arrive_after_s));
  try {
    StreamClient client;
    const pb::Welcome welcome = open_session(cfg, client, r);
    open = true;
    if (progress) progress->open++;
    Trace trace = cfg.traces ? *cfg.traces->get(cfg.trace, cfg.scene.get(), welcome, r.width, r.height)
                             : make_load_trace(cfg.trace, cfg.scene.get(), welcome, r.width, r.height);
    if (trace.empty()) throw std::runtime_error("empty trace " + cfg.trace);
    PoseLoop(cfg, r, client, std::move(trace), welcome).run();
  } catch (const Refused& e) {
    r.refused = true;
    r.refusal = pb::ErrorCode_Name(e.error().code()) + ": " + e.error().reason();
  } catch (const std::exception& e) {
    note_error(r, e.what());
  }
  if (progress) {
    if (open) progress->open--;
    if (r.refused) progress->refused++;
    if (r.errors > 0) progress->failed++;
    progress->finished++;
  }
  return r;
}

}  // namespace catgs::loadgen
