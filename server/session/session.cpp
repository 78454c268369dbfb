#include "session/session.h"

#include <boost/asio/bind_executor.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <filesystem>
#include <random>

#include <nlohmann/json.hpp>

#include "base/allocation_faults.h"
#include "camera/camera.h"
#include "renderer/device_memory.h"
#include "encode/frame_encoding.h"
#include "session/annotations.h"
#include "session/depth_probe.h"
#include "process/first_view.h"

namespace catgs::server {

namespace {

std::string random_session_id() {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(rng()));
  return buf;
}

// base .. 2 x base ms, uniformly (see kServerFullRetryMs in session.h).
std::uint32_t jittered(std::uint32_t base) {
  static thread_local std::mt19937 rng{std::random_device{}()};
  return base + std::uniform_int_distribution<std::uint32_t>(0, base)(rng);
}

void set_vec3(pb::Vec3* v, const glm::vec3& x) {
  v->set_x(x.x);
  v->set_y(x.y);
  v->set_z(x.z);
}

constexpr auto kTick = std::chrono::milliseconds(250);
constexpr std::size_t kMaxQueuedMessages = 256;  // non-frame messages a non-reader may pile up
// DepthRequests of one session probing at once: a page waits for each answer (walk mode keeps
// two in flight); more are answered with an error rather than queued behind the probes.
constexpr int kMaxDepthsInFlight = 4;

}  // namespace

Session::Session(ConnId id, SessionShared& shared)
    : id_(id),
      shared_(shared),
      strand_(boost::asio::make_strand(shared.io)),
      tick_(strand_),
      hello_timer_(strand_),
      peer_(shared.transport.peer(id)),
      stream_(shared_, id_, *this),
      exports_(shared_, id_, *this) {
  shared_.metrics.connections_open++;
  const auto now = Clock::now();
  const RateLimitSettings& r = shared_.settings.rate_limits;
  ping_bucket_ = TokenBucket(r.ping, now);
  key_frame_bucket_ = TokenBucket(r.key_frame, now);
  resize_bucket_ = TokenBucket(r.resize, now);
  quality_bucket_ = TokenBucket(r.quality, now);
  depth_bucket_ = TokenBucket(r.depth, now);
  save_bucket_ = TokenBucket(r.save, now);
  export_bucket_ = TokenBucket(r.export_video, now);
  last_message_ = now;
}

// An open socket that never says Hello would otherwise hold its descriptor and a --max-pre-hello
// slot for ever (issue 22: 2000 idle sockets stayed open).
void Session::start() {
  // Armed on the strand like every other use of the timer; posted before any message of this
  // connection can be, so a Hello always finds it armed.
  boost::asio::post(strand_, [self = shared_from_this()] {
    if (self->state_ != State::awaiting_hello) return;
    self->hello_timer_.expires_after(std::chrono::milliseconds(self->shared_.settings.hello_timeout_ms));
    self->hello_timer_.async_wait([self](const boost::system::error_code& ec) {
      if (ec || self->state_ != State::awaiting_hello) return;
      self->shared_.metrics.count(ServerMetrics::Timeout::hello);
      self->fail(pb::ERROR_TIMEOUT,
                 "no Hello within " + std::to_string(self->shared_.settings.hello_timeout_ms) + " ms");
    });
  });
}

Session::~Session() {
  shared_.metrics.connections_open--;
  if (placed_) shared_.gpus.release(gpu_, memory_reserved_, memory_held_);
}

void Session::on_out_of_memory(const std::string& error, int streak) {
  // The GPU's memory ran out while this session's buffers grew (the estimate admitted it, but
  // another process, or a view far denser than the estimate, took the room): the frame is lost,
  // not the session. Its later frames are drawn in passes within the list buffers it has, and
  // the next pose renders as usual. Only a session that still cannot draw a frame after
  // kMaxOutOfMemoryFrames in a row is ended, as full, with a retry hint.
  shared_.metrics.render_out_of_memory_total++;
  const std::uint64_t budget = stream_.halve_list_budget();
  std::cerr << "[session " << id_ << "] out of device memory (" << error << "): frame dropped, list budget now "
            << memory_text(budget) << "\n";
  if (streak >= kMaxOutOfMemoryFrames)
    return fail(pb::ERROR_SERVER_FULL,
                "server full: its GPU's memory cannot hold this session's frames (" + error + ")", false,
                jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  stream_.retry_lost_frame();  // a still camera sends no other pose: its frame comes anyway
  stream_.admit();
}

bool Session::splat_budget_full() {
  const LodSettings& lod = shared_.settings.frame.lod;
  if (gpu_ < 0 || !lod.auto_budget || lod.splat_budget > 0 ||
      !shared_.metrics.gpu_budget_short(gpu_, ServerMetrics::steady_now_ms(), kBudgetShortMs))
    return false;
  shared_.metrics.splat_budget_refusals_total++;
  char bound[32];
  std::snprintf(bound, sizeof(bound), "%.2f", lod.coarsest_bound_px());
  fail(pb::ERROR_SERVER_FULL,
       "server full: GPU " + std::to_string(gpu_) + "'s sessions already draw at the coarsest bound allowed (" + bound +
           " px, --lod-max-error) over its splat budget",
       false, jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  return true;
}

bool Session::reserve_buffers(Renderer& renderer) {
  // The buffers this scene's sessions grew to (none yet: the renderer's first guess), for this
  // viewport: allocated now, so that the frames allocate only to grow past them, and a GPU that
  // another process filled refuses the visitor here rather than mid-tour.
  const BufferShape shape{scene_->session_gaussians_peak->load(), scene_->session_list_peak->load()};
  try {
    renderer.reserve_buffers(stream_.width(), stream_.height(), shape);
  } catch (const OutOfMemoryError& e) {
    shared_.metrics.memory_refusals_total++;
    shared_.metrics.memory_refusals_driver_total++;
    fail(pb::ERROR_SERVER_FULL,
         std::string("server full: its GPU could not hold this session's buffers (") + e.what() +
             "; another process may hold its memory)",
         false, jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
    return false;
  }
  update_memory(renderer.device_buffer_bytes(), renderer.buffer_shape());
  return true;
}

std::uint64_t Session::memory_estimate(int width, int height) const {
  // The CUDA core's buffers follow the chunks a view keeps (records.h Projected): its first
  // guess of them, or what this scene's sessions' buffers grew to, or this session's own.
  const std::uint64_t first = first_session_device_bytes(
      scene_->model->size(), width, height, shared_.render_options.pipeline, shared_.render_options.list_budget);
  return std::max({first, memory_peak_, scene_->session_bytes_peak->load()});
}

namespace {
// Raises `peak` to `value` where it is more (other sessions raise it too).
void raise(std::atomic<std::uint64_t>& peak, std::uint64_t value) {
  for (std::uint64_t seen = peak.load(); value > seen && !peak.compare_exchange_weak(seen, value);) {}
}
}  // namespace

void Session::update_memory(std::uint64_t buffer_bytes, const BufferShape& shape) {
  memory_peak_ = std::max(memory_peak_, buffer_bytes);
  raise(*scene_->session_bytes_peak, buffer_bytes);
  raise(*scene_->session_gaussians_peak, shape.gaussians);
  raise(*scene_->session_list_peak, shape.list_entries);
  if (placed_ && buffer_bytes > 0 && buffer_bytes != memory_held_) {
    shared_.gpus.hold(gpu_, memory_held_, buffer_bytes);
    memory_held_ = buffer_bytes;
  }
  const std::uint64_t want = memory_estimate(stream_.width(), stream_.height());
  if (!placed_ || want == memory_reserved_) return;
  if (!shared_.gpus.update(gpu_, memory_reserved_, want))
    std::cerr << "[session " << id_ << "] device memory: its buffers (" << memory_text(want)
              << ") take its GPU past its capacity\n";
  memory_reserved_ = want;
}

void Session::post_message(MessageKind kind, std::string bytes) {
  // Arrival is stamped on the transport thread (the strand may wait for a busy pool thread).
  const auto received = Clock::now();
  boost::asio::post(strand_, [self = shared_from_this(), kind, bytes = std::move(bytes), received] {
    try {
      self->handle_message(kind, bytes, received);
    } catch (const std::exception& e) {
      // Anything unexpected ends this session only.
      self->fail(pb::ERROR_INTERNAL, std::string("internal error: ") + e.what());
    }
  });
}

void Session::post_sent(const SocketSample& socket) {
  // Stamped here, on the transport thread: the strand handler may wait for a pool thread that
  // is busy rendering, and that wait is not send time.
  const auto written = Clock::now();
  boost::asio::post(strand_, [self = shared_from_this(), written, socket] {
    self->stream_.on_sent(written, socket);
    self->exports_.pump();  // a file's next chunks once the queue has room
  });
}

void Session::post_closed() {
  gone_ = true;  // now, not on the strand: a render job about to start can be skipped at once
  boost::asio::post(strand_, [self = shared_from_this()] {
    self->end_open_state();
    self->state_ = State::closed;
    self->stream_.drop_pending();
    self->tick_.cancel();
    self->hello_timer_.cancel();
  });
}

void Session::post_shutdown() {
  boost::asio::post(strand_, [self = shared_from_this()] {
    self->fail(pb::ERROR_SHUTTING_DOWN, "server shutting down", false, jittered(kShuttingDownRetryMs));
  });
}

ViewportLimit Session::viewport_limit() const {
  return {shared_.settings.max_viewport_width, shared_.settings.max_viewport_height};
}

void Session::end_open_state() {
  if (stream_.drop_pending()) shared_.metrics.dropped_frames_total++;  // a pose that will never be rendered
  // A closed page gets no file: its rendering stops and its file goes.
  exports_.end(ServerMetrics::ExportEnd::cancelled);
  scene_use_.reset();  // the scene may be unloaded now (a wait for its load is withdrawn)
  if (counted_open_) {
    counted_open_ = false;
    shared_.metrics.sessions_open--;
  }
}

std::string Session::label() const {
  return "[session " + std::to_string(id_) + (session_id_.empty() ? "" : " " + session_id_) + "]";
}

void Session::send(const pb::ServerMessage& message) {
  std::string bytes;
  message.SerializeToString(&bytes);
  shared_.transport.send(id_, std::move(bytes), /*counted=*/false);
}

void Session::fail(pb::ErrorCode code, const std::string& reason, bool drop_queued, std::uint32_t retry_after_ms) {
  if (state_ == State::closed) return;
  state_ = State::closed;
  gone_ = true;
  tick_.cancel();
  hello_timer_.cancel();
  end_open_state();
  shared_.metrics.session_errors_total++;
  std::cerr << "[session " << id_ << (session_id_.empty() ? "" : " " + session_id_) << " " << peer_ << "] "
            << pb::ErrorCode_Name(code) << ": " << reason << "\n";
  pb::ServerMessage m;
  m.mutable_error()->set_code(code);
  m.mutable_error()->set_reason(reason);
  m.mutable_error()->set_retry_after_ms(retry_after_ms);
  std::string bytes;
  m.SerializeToString(&bytes);
  shared_.transport.close(id_, std::move(bytes), drop_queued);
}

bool Session::within(TokenBucket& bucket, ServerMetrics::Limit limit, const char* what, const RateSpec& spec) {
  const auto now = Clock::now();
  if (bucket.take(now)) return true;
  shared_.metrics.count(limit);
  // Queued frames are dropped: the Error goes out next, not behind frames a flooding peer may be
  // too busy to read before the close's grace time ends (the page then showed no reason).
  fail(pb::ERROR_RATE_LIMITED, std::string("too many ") + what + " (limit " + describe(spec) + ", --rate-limits)", true,
       bucket.wait_ms(now));
  return false;
}

void Session::handle_message(MessageKind kind, const std::string& bytes, Clock::time_point received) {
  if (state_ == State::closed) return;
  last_message_ = received;
  if (kind == MessageKind::text) return fail(pb::ERROR_MALFORMED, "text frames are not allowed");
  if (kind == MessageKind::oversize) return fail(pb::ERROR_MALFORMED, "message larger than 64 KiB");
  pb::ClientMessage msg;
  if (!msg.ParseFromString(bytes)) return fail(pb::ERROR_MALFORMED, "message does not parse as ClientMessage");
  if (msg.body_case() == pb::ClientMessage::BODY_NOT_SET)
    return fail(pb::ERROR_MALFORMED, "ClientMessage without a body");

  if (state_ == State::awaiting_hello) {
    if (msg.body_case() != pb::ClientMessage::kHello)
      return fail(pb::ERROR_PROTOCOL, "the first message must be Hello");
    return handle_hello(msg.hello());
  }
  switch (msg.body_case()) {
    case pb::ClientMessage::kHello:
      return fail(pb::ERROR_PROTOCOL, "second Hello");
    case pb::ClientMessage::kPose:
      return handle_pose(msg.pose(), received);
    case pb::ClientMessage::kResize: {
      const RateLimitSettings& r = shared_.settings.rate_limits;
      if (!within(resize_bucket_, ServerMetrics::Limit::resize, "Resizes", r.resize)) return;
      Viewport v;
      if (auto bad = check_viewport(msg.resize().viewport_width(), msg.resize().viewport_height(), viewport_limit(), v))
        return fail(bad->code, bad->reason);
      stream_.set_viewport(v.width, v.height);      // the encoder is rebuilt at the new size: an IDR
      if (state_ == State::open) update_memory(0);  // the estimate at the new size
      return;
    }
    case pb::ClientMessage::kPing: {
      if (!within(ping_bucket_, ServerMetrics::Limit::ping, "Pings", shared_.settings.rate_limits.ping)) return;
      if (!std::isfinite(msg.ping().client_time_ms()))
        return fail(pb::ERROR_INVALID_ARGUMENT, "Ping time is NaN or Inf");
      pb::ServerMessage m;
      m.mutable_pong()->set_client_time_ms(msg.ping().client_time_ms());
      m.mutable_pong()->set_server_time_ms(
          std::chrono::duration<double, std::milli>(Clock::now().time_since_epoch()).count());
      return send(m);
    }
    case pb::ClientMessage::kKeyFrameRequest:
      // Each one makes the next frame an IDR (many times a P frame's bytes and encode time).
      if (!within(key_frame_bucket_, ServerMetrics::Limit::key_frame, "KeyFrameRequests",
                  shared_.settings.rate_limits.key_frame))
        return;
      stream_.request_idr();
      return;
    case pb::ClientMessage::kQuality:
      if (!within(quality_bucket_, ServerMetrics::Limit::quality, "Quality messages",
                  shared_.settings.rate_limits.quality))
        return;
      if (auto bad = check_quality(msg.quality())) return fail(bad->code, bad->reason);
      stream_.set_max_bitrate(static_cast<int>(msg.quality().max_bitrate_kbps()));  // an IDR
      return;
    case pb::ClientMessage::kDepthRequest:
      return handle_depth(msg.depth_request());
    case pb::ClientMessage::kSaveAnnotations:
      return handle_save_annotations(msg.save_annotations());
    case pb::ClientMessage::kExportVideo:
      return handle_export(msg.export_video());
    case pb::ClientMessage::kExportCancel:
      return exports_.cancel(msg.export_cancel());
    default:
      return fail(pb::ERROR_MALFORMED, "unknown message");
  }
}

bool Session::admit(const pb::Hello& hello) {
  std::uint32_t retry_ms = 0;
  if (!shared_.peers.take_hello(peer_, retry_ms)) {
    shared_.metrics.count(ServerMetrics::Limit::hello);
    fail(pb::ERROR_RATE_LIMITED,
         "too many Hellos from " + peer_ + " (limit " + describe(shared_.settings.rate_limits.hello) +
             ", --rate-limits)",
         false, retry_ms);
    return false;
  }
  if (shared_.settings.tokens.empty()) return true;
  // The failure limit is checked before the token is: past it, a guess is not even compared.
  if (!shared_.peers.may_try_token(peer_, retry_ms)) {
    shared_.metrics.count(ServerMetrics::Limit::auth);
    fail(pb::ERROR_RATE_LIMITED, "too many wrong tokens from " + peer_ + " (--rate-limits auth)", false, retry_ms);
    return false;
  }
  role_ = shared_.settings.tokens.role_of(hello.token());
  if (role_ == Role::none) {
    shared_.peers.token_failed(peer_);
    shared_.metrics.count(ServerMetrics::Unauthorized::hello);
    fail(pb::ERROR_UNAUTHORIZED, "wrong or missing token");
    return false;
  }
  return true;
}

void Session::handle_hello(const pb::Hello& hello) {
  hello_timer_.cancel();
  Viewport v;
  if (auto bad = check_hello(hello, viewport_limit(), v)) return fail(bad->code, bad->reason);
  if (!admit(hello)) return;
  if (hello.codecs_size() > 0) {
    bool h264 = false;
    for (int c : hello.codecs()) {
      h264 = h264 || c == pb::CODEC_H264;
      client_av1_ = client_av1_ || c == pb::CODEC_AV1;
    }
    // A stream may move to H.264 whenever AV1 stops paying (sessions join, the link limits it):
    // an AV1-only client is served only where AV1 is forced on.
    if (!h264 && !(client_av1_ && shared_.settings.frame.encoder_policy.av1 == "on" && shared_.encoder_kind == "x264"))
      return fail(pb::ERROR_INVALID_ARGUMENT, client_av1_ ? "client does not accept H.264 (AV1 alone needs --av1 on)"
                                                          : "client accepts no codec this server streams (H.264, AV1)");
  }
  const std::optional<std::size_t> scene = shared_.scenes.find(hello.scene());
  if (!scene)
    // The name comes from the client: only its first 64 bytes go into the reason.
    return fail(pb::ERROR_INVALID_ARGUMENT, "no scene '" + hello.scene().substr(0, 64) +
                                                "' on this server (it has: " + shared_.scenes.names() + ")");
  if (shared_.draining)
    return fail(pb::ERROR_SHUTTING_DOWN, "server draining: connect again", false, jittered(kShuttingDownRetryMs));
  if (++shared_.metrics.sessions_open > shared_.settings.max_sessions) {
    shared_.metrics.sessions_open--;
    // A hint, not a promise: a page that waits this long (or a fresh connection that the Service
    // sends to another replica) is likely to get in.
    return fail(pb::ERROR_SERVER_FULL, "server full (" + std::to_string(shared_.settings.max_sessions) + " sessions)",
                false, jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  }
  // The cores are counted like device memory (issue 92): with --x264-floor, a visitor whose
  // stream, beside the live ones, the encoders' share of the cores could not hold at the floor's
  // preset is refused here rather than stepping every stream below the picture the operator set.
  const EncoderPolicy& policy = shared_.settings.frame.encoder_policy;
  if (shared_.encoder_kind == "x264" &&
      !cores_hold(policy, v.width, v.height, kStreamFps, static_cast<int>(shared_.metrics.sessions_open.load()))) {
    shared_.metrics.sessions_open--;
    shared_.metrics.core_refusals_total++;
    return fail(pb::ERROR_SERVER_FULL,
                "server full: its cores cannot encode another " + std::to_string(v.width) + "x" +
                    std::to_string(v.height) + " stream at x264 " + kPresetLadder[policy.floor_step].name +
                    " (--x264-floor)",
                false, jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  }
  counted_open_ = true;
  shared_.metrics.sessions_total++;
  shared_.transport.said_hello(id_);  // no longer counts against --max-pre-hello
  state_ = State::loading;
  stream_.set_viewport(v.width, v.height);  // a Resize while the scene loads replaces it
  load_progress_ = hello.load_progress();
  client_name_ = hello.client_name().substr(0, 128);
  // The scene is there (ready is posted at once) or loads on a thread of its own: this strand
  // and every other session go on meanwhile. Both callbacks come back through the strand.
  auto self = shared_from_this();
  scene_use_ = shared_.scenes.acquire(
      *scene,
      [self](int percent, std::uint64_t done, std::uint64_t total) {
        boost::asio::post(self->strand_,
                          [self, percent, done, total] { self->send_load_progress(percent, done, total); });
      },
      [self](std::shared_ptr<const LoadedScene> loaded, const std::string& error) {
        boost::asio::post(self->strand_, [self, loaded = std::move(loaded), error] {
          self->on_scene_ready(std::move(loaded), error);
        });
      });
  // A load that hangs (a stalled network file system) must not hold this session for ever: the
  // Hello timer, idle since the Hello, bounds the wait (on_scene_ready cancels it). Ending the
  // session withdraws its wait (scene_use_); the load goes on for whoever asks next.
  hello_timer_.expires_after(std::chrono::milliseconds(shared_.settings.scene_load_timeout_ms));
  hello_timer_.async_wait([self](const boost::system::error_code& ec) {
    if (ec || self->state_ != State::loading) return;
    self->shared_.metrics.count(ServerMetrics::Timeout::scene_load);
    self->fail(pb::ERROR_TIMEOUT, "scene '" + self->shared_.scenes.name(self->scene_use_->index()) +
                                      "' did not load within " +
                                      std::to_string(self->shared_.settings.scene_load_timeout_ms) + " ms");
  });
}

void Session::send_load_progress(int percent, std::uint64_t done, std::uint64_t total) {
  // Callbacks from the loading thread and from acquire() may arrive out of order: only a rise
  // goes out, and nothing after Welcome.
  if (state_ != State::loading || !load_progress_ || percent <= progress_sent_) return;
  progress_sent_ = percent;
  pb::ServerMessage m;
  pb::LoadProgress* p = m.mutable_load_progress();
  p->set_scene_name(shared_.scenes.name(scene_use_->index()));
  p->set_percent(static_cast<std::uint32_t>(percent));
  p->set_gaussians_read(static_cast<std::uint32_t>(std::min<std::uint64_t>(done, UINT32_MAX)));
  p->set_gaussians_total(static_cast<std::uint32_t>(std::min<std::uint64_t>(total, UINT32_MAX)));
  send(m);
}

void Session::on_scene_ready(std::shared_ptr<const LoadedScene> scene, const std::string& error) {
  if (state_ != State::loading) return;  // closed meanwhile
  hello_timer_.cancel();                 // the scene-load bound
  if (!scene)
    return fail(pb::ERROR_INTERNAL,
                "scene '" + shared_.scenes.name(scene_use_->index()) + "' failed to load: " + error);
  scene_ = std::move(scene);
  // A GPU whose memory holds this session's buffers, the least busy of those (issue 61): a
  // visitor no GPU can hold is refused here, at the door, rather than ended mid-tour when an
  // allocation fails.
  const std::uint64_t need = memory_estimate(stream_.width(), stream_.height());
  shared_.next_session_bytes = need;
  const GpuAssignment::Placement place = shared_.gpus.place(need);
  if (!place.placed) {
    shared_.metrics.memory_refusals_total++;
    if (place.driver_binds) shared_.metrics.memory_refusals_driver_total++;
    return fail(pb::ERROR_SERVER_FULL, "server full: " + place.why, false,
                jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  }
  placed_ = true;
  memory_reserved_ = need;
  gpu_ = shared_.renderer_kind == "cuda" ? place.device : -1;
  if (splat_budget_full()) return;
  std::unique_ptr<Renderer> renderer;
  try {
    renderer = make_renderer(shared_.renderer_kind, scene_->model, shared_.render_options, nullptr, std::max(gpu_, 0));
  } catch (const OutOfMemoryError& e) {  // its first buffers: a full GPU, at the door
    shared_.metrics.memory_refusals_total++;
    return fail(pb::ERROR_SERVER_FULL,
                std::string("server full: its GPU could not hold this session's renderer (") + e.what() + ")", false,
                jittered(static_cast<std::uint32_t>(shared_.settings.full_retry_ms)));
  } catch (const std::exception& e) {  // e.g. no device memory left for another scene copy
    return fail(pb::ERROR_INTERNAL, "renderer for scene '" + scene_->model->name + "': " + e.what());
  }
  if (!reserve_buffers(*renderer)) return;
  // NVENC takes CUDA frames in one job; every other encoder gets the two-stage pipeline.
  const bool pipelined = !(shared_.encoder_kind == "nvenc" && renderer->name() == "cuda");
  stream_.open(std::move(renderer), scene_->model, gpu_, pipelined, client_av1_ && shared_.encoder_kind == "x264",
               scene_->content_rates);
  state_ = State::open;
  session_id_ = random_session_id();

  pb::ServerMessage m;
  pb::Welcome* w = m.mutable_welcome();
  w->set_session_id(session_id_);
  w->set_scene_name(scene_->model->name);
  set_vec3(w->mutable_scene_bounds()->mutable_min(), scene_->bounds.min);
  set_vec3(w->mutable_scene_bounds()->mutable_max(), scene_->bounds.max);
  const CameraPose start = first_view_pose(scene_->frame, stream_.width(), stream_.height());
  pb::Pose* p = w->mutable_initial_pose();
  p->set_sequence(0);
  set_vec3(p->mutable_position(), start.position);
  p->mutable_orientation()->set_w(start.orientation.w);
  p->mutable_orientation()->set_x(start.orientation.x);
  p->mutable_orientation()->set_y(start.orientation.y);
  p->mutable_orientation()->set_z(start.orientation.z);
  p->set_vertical_fov_deg(start.vertical_fov_deg);
  set_vec3(w->mutable_orbit_centre(), scene_->frame.orbit_centre);
  set_vec3(w->mutable_up(), scene_->frame.up);
  w->set_scene_scale(scene_->frame.scene_scale);
  w->set_can_export(exports_.may_export(role_));
  const int live = static_cast<int>(std::max<std::int64_t>(1, shared_.metrics.sessions_open.load()));
  const bool av1 = stream_.first_frame_av1(live);
  w->set_codec(av1 ? pb::CODEC_AV1 : pb::CODEC_H264);
  w->set_width(static_cast<std::uint32_t>(stream_.width()));
  w->set_height(static_cast<std::uint32_t>(stream_.height()));
  w->set_renderer(stream_.renderer_name());
  w->set_encoder(av1 ? "av1" : shared_.encoder_kind);
  w->set_pipeline(pipeline_name(shared_.render_options.pipeline));
  send(m);
  std::cerr << label() << " open " << stream_.width() << "x" << stream_.height() << " scene '" << scene_->model->name
            << "' client '" << client_name_ << "'\n";
  last_stats_ = Clock::now();
  stream_.opened(last_stats_);
  last_message_ = last_stats_;  // a load's wait is not the client's silence
  send_annotations();
  arm_tick();
  stream_.admit();  // a Pose sent before Welcome
}

void Session::handle_pose(const pb::Pose& pose, Clock::time_point received) {
  CameraPose cam;
  if (auto bad = check_pose(pose, cam)) return fail(bad->code, bad->reason);
  std::optional<StereoPose> eyes;
  if (auto bad = check_stereo(pose, eyes)) return fail(bad->code, bad->reason);
  last_pose_ = cam;
  stream_.on_pose(pose, cam, eyes, received);
}

void Session::handle_depth(const pb::DepthRequest& request) {
  if (!within(depth_bucket_, ServerMetrics::Limit::depth, "DepthRequests", shared_.settings.rate_limits.depth)) return;
  // A request that cannot be answered gets an answer that says why; the session goes on (a pixel
  // outside the view is the page's race with a Resize as often as a bug).
  auto refuse = [this, &request](const std::string& why) {
    pb::ServerMessage m;
    m.mutable_depth_result()->set_request_id(request.request_id());
    m.mutable_depth_result()->set_error(why);
    send(m);
  };
  if (state_ != State::open) return refuse("the scene is not open yet");
  DepthQuery query;
  if (auto bad = check_depth_request(request, last_pose_, Viewport{stream_.width(), stream_.height()}, query))
    return refuse(bad->reason);
  if (depths_in_flight_ >= kMaxDepthsInFlight)
    return refuse("already " + std::to_string(kMaxDepthsInFlight) + " DepthRequests in flight: wait for an answer");
  ++depths_in_flight_;
  boost::asio::post(shared_.io, [self = shared_from_this(), scene = scene_, query, id = request.request_id()] {
    pb::ServerMessage m;
    *m.mutable_depth_result() = answer_depth(*scene->model, &scene->chunks, query, id);
    boost::asio::post(self->strand_, [self, m = std::move(m)] {
      self->depths_in_flight_--;
      if (self->state_ == State::open) self->send(m);
    });
  });
}

// An annotations error as the client sees it: the file by its name, without the server's folders
// (the log keeps the whole path).
static std::string client_error(std::string error, const std::string& scene_path) {
  const std::string folder = std::filesystem::path(scene_path).parent_path().string();
  if (folder.empty()) return error;
  for (std::size_t at; (at = error.find(folder + "/")) != std::string::npos;) error.erase(at, folder.size() + 1);
  return error;
}

void Session::send_annotations() {
  const AnnotationsFile file = read_annotations(scene_->path);
  if (!file.error.empty())
    std::cerr << "[session " << id_ << " " << session_id_ << "] annotations not shown: " << file.error << "\n";
  pb::ServerMessage m;
  pb::Annotations* a = m.mutable_annotations();
  a->set_json(file.json);
  a->set_error(client_error(file.error, scene_->path));
  a->set_can_save(role_ >= Role::author);
  send(m);
}

void Session::handle_save_annotations(const pb::SaveAnnotations& save) {
  if (!within(save_bucket_, ServerMetrics::Limit::save, "SaveAnnotations", shared_.settings.rate_limits.save)) return;
  pb::ServerMessage m;
  pb::Annotations* a = m.mutable_annotations();
  a->set_can_save(role_ >= Role::author);
  // A server without tokens has no authors: anyone who reaches it could otherwise write files.
  if (!a->can_save()) {
    a->set_error(shared_.settings.tokens.empty() ? "this server saves no annotations (it has no author tokens)"
                                                 : "saving annotations needs an author or admin token");
  } else if (state_ != State::open) {
    a->set_error("the scene is not open yet");
  } else {
    try {
      a->set_json(write_annotations(scene_->path, save.json()));
      a->set_saved(true);
      std::cerr << "[session " << id_ << " " << session_id_ << "] saved " << annotations_path(scene_->path) << "\n";
    } catch (const std::exception& e) {
      std::cerr << "[session " << id_ << " " << session_id_ << "] annotations not saved: " << e.what() << "\n";
      a->set_error(client_error(e.what(), scene_->path));
    }
  }
  send(m);
}

void Session::handle_export(const pb::ExportVideoRequest& request) {
  if (!within(export_bucket_, ServerMetrics::Limit::export_video, "ExportVideoRequests",
              shared_.settings.rate_limits.export_video))
    return;
  exports_.start(request, role_, state_ == State::open, scene_ ? scene_->model : nullptr, gpu_);
}

void Session::arm_tick() {
  tick_.expires_after(kTick);
  tick_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (!ec) self->on_tick();
  });
}

void Session::on_tick() {
  if (state_ != State::open) return;
  const auto now = Clock::now();
  const auto timeout = std::chrono::milliseconds(shared_.settings.slow_client_timeout_ms);
  if (stream_.unread_for(now, timeout))
    return fail(pb::ERROR_TOO_SLOW,
                "frames unread for " + std::to_string(shared_.settings.slow_client_timeout_ms) + " ms",
                /*drop_queued=*/true);
  if (shared_.transport.queued(id_) > kMaxQueuedMessages)
    return fail(pb::ERROR_TOO_SLOW, "client does not read its messages", /*drop_queued=*/true);
  // A session that says nothing (no pose, no Ping) for this long holds a slot for nobody.
  if (now - last_message_ > std::chrono::milliseconds(shared_.settings.silent_timeout_ms)) {
    shared_.metrics.count(ServerMetrics::Timeout::silent);
    return fail(pb::ERROR_TIMEOUT, "no message for " + std::to_string(shared_.settings.silent_timeout_ms) + " ms");
  }
  if (now - last_stats_ >= std::chrono::seconds(1)) send_stats();
  exports_.pump();
  stream_.on_tick(now);
  arm_tick();
}

void Session::send_stats() {
  const auto now = Clock::now();
  const double seconds = std::max(1e-3, ms_between(last_stats_, now) / 1000.0);
  pb::ServerMessage m;
  pb::Stats* s = m.mutable_stats();
  stream_.fill_stats(*s, seconds);
  s->set_device_memory_mib(static_cast<std::uint32_t>(memory_reserved_ >> 20));
  // Draining: the client learns when this session will end (the page says so), within a second of
  // SIGTERM, rather than only from the Error at the deadline.
  if (shared_.draining) {
    const double left = ms_between(now, shared_.drain_deadline.load());
    s->set_drain_ms_left(static_cast<std::uint32_t>(std::clamp(left, 1.0, 3.6e6)));
  }
  send(m);
  shared_.metrics.session_device_bytes.observe(static_cast<double>(memory_reserved_));
  last_stats_ = now;
}

}  // namespace catgs::server
