// The frame pipeline of a Session (session.h): a pose becomes a render job on a render lane, the
// rendered I420 picture an encode job on the worker pool, the access unit a Frame handed to the
// transport. Latest pose wins; a rendered frame that would miss its display slot is skipped
// before its encode (frame_pacing.h); adaptive quality scales the size (adaptive_quality.h); the
// encoder is configured by the encoder policy (encode/encoder_policy.h). The protocol state
// machine that feeds it is session.cpp.
#include "session/session.h"

#include <boost/asio/post.hpp>

#include <algorithm>

#include "camera/camera.h"
#include "encode/encoder_policy.h"
#include "session/link_rate.h"

namespace catgs::server {

namespace {

// The stream's nominal frame rate: the browser's pose rate (its time base and the VBV's budget).
constexpr int kStreamFps = 60;

}  // namespace

void Session::maybe_start_render() {
  // Frames admitted but not yet written: those the transport holds and the one being encoded.
  const int admitted = in_flight_ + (encoding_ ? 1 : 0);
  if (state_ != State::open || rendering_ || rendered_ || !pending_ || admitted >= shared_.options.max_frames_in_flight)
    return;
  std::unique_ptr<Yuv420Image> planes;
  if (pipelined_) {
    if (free_planes_.empty()) return;  // both buffers busy (one rendering is excluded above)
    planes = std::move(free_planes_.back());
    free_planes_.pop_back();
  }
  // Adaptive quality scales the size (a refine frame is full size); a new size is an IDR.
  const int level = shared_.options.adaptive_quality && !pending_->full_size ? quality_.level() : 0;
  Job job{*pending_, AdaptiveQuality::scaled_side(width_, level), AdaptiveQuality::scaled_side(height_, level),
          force_idr_,
          // Pipelined, the number is given at the encode (maybe_start_encode): a frame skipped
          // before its encode must leave no gap, as Frame sequences rise by one from 0.
          pipelined_ ? 0 : next_frame_sequence_++, last_send_ms_, max_bitrate_kbps_, level};
  // The link's cap against the policy's rate at this size (link_rate.h), both in bits a second
  // on the wire: the VBV's rate is per frame at the nominal kStreamFps, so a stream at fewer
  // frames a second sends that share of it.
  const double fps_share = std::clamp(link_.frame_rate() / kStreamFps, 0.05, 1.0);
  const int vbv_ceiling =
      target_bitrate_kbps(shared_.options.encoder_policy, job.width, job.height, kStreamFps, max_bitrate_kbps_);
  link_ceiling_kbps_ = vbv_ceiling > 0 ? std::max(1, static_cast<int>(vbv_ceiling * fps_share)) : 0;
  if (shared_.options.link_control && link_.limited())
    job.link_kbps =
        std::max(1, static_cast<int>(link_.cap_kbps(link_ceiling_kbps_) * link_.encoder_gain() / fps_share));
  last_started_ = pending_;
  last_started_->full_size = false;
  pending_.reset();
  force_idr_ = false;
  rendering_ = true;
  const std::int64_t pixels = static_cast<std::int64_t>(job.width) * job.height;
  if (!pipelined_) {
    shared_.renders.post(id_, pixels, [self = shared_from_this(), job] {
      JobResult result = self->run_render_and_encode(job);
      boost::asio::post(self->strand_, [self, result = std::move(result)]() mutable {
        self->rendering_ = false;
        self->on_job_done(std::move(result));
      });
    });
    return;
  }
  shared_.renders.post(id_, pixels, [self = shared_from_this(), job, planes = std::move(planes)]() mutable {
    Rendered frame = self->run_render(job, std::move(planes));
    boost::asio::post(self->strand_, [self, frame = std::move(frame)]() mutable {
      self->rendering_ = false;
      if (!frame.error.empty()) {
        self->free_planes_.push_back(std::move(frame.planes));
        JobResult failed;
        failed.error = frame.error;
        failed.over_budget = frame.over_budget;
        return self->on_job_done(std::move(failed));
      }
      self->pacing_.on_rendered(frame.queue_ms + frame.render_ms + frame.convert_ms);
      self->rendered_ = std::move(frame);
      self->maybe_start_encode();
      self->maybe_start_render();
    });
  });
}

void Session::maybe_start_encode() {
  if (encoding_ || !rendered_) return;
  if (state_ != State::open) {  // nobody to send it to
    free_planes_.push_back(std::move(rendered_->planes));
    rendered_.reset();
    shared_.metrics.dropped_frames_total++;
    return;
  }
  // Past its display slot with a newer pose waiting: the encoder's time goes to the newer pose.
  // A refine frame (adaptive quality) or a forced IDR is never skipped: nothing else carries it.
  if (!rendered_->job.pose.full_size && !rendered_->job.force_idr &&
      pacing_.skip_before_encode(rendered_->job.pose.received, Clock::now(), pending_.has_value())) {
    free_planes_.push_back(std::move(rendered_->planes));
    rendered_.reset();
    poses_skipped_++;
    shared_.metrics.deadline_skips_total++;
    maybe_start_render();
    return;
  }
  encoding_ = true;
  rendered_->job.frame_sequence = next_frame_sequence_++;  // in encode (= send) order, no gaps
  auto frame = std::make_shared<Rendered>(std::move(*rendered_));
  rendered_.reset();
  boost::asio::post(shared_.io, [self = shared_from_this(), frame] {
    JobResult result = self->run_encode(*frame);
    boost::asio::post(self->strand_, [self, frame, result = std::move(result)]() mutable {
      self->encoding_ = false;
      self->free_planes_.push_back(std::move(frame->planes));
      self->on_job_done(std::move(result));
      self->maybe_start_encode();
      self->maybe_start_render();  // the rendered slot may have just been freed
    });
  });
}

void Session::render_into(const Job& job, const Yuv420Target& target, Rendered& r) {
  const auto t_start = Clock::now();
  const Camera camera = Camera::from_pose(job.pose.pose.position, job.pose.pose.orientation,
                                          job.pose.pose.vertical_fov_deg, job.width, job.height);
  // Rendered and colour-converted where the frame is (on the GPU for the CUDA core: a host
  // target gets only the I420 planes). The client's clock drives the catgs motion predictor.
  r.convert_ms = renderer_->render_yuv420_at(camera, job.pose.client_time_ms / 1000.0, target);
  r.render_key_frame = renderer_->last_stats().key_frame;
  r.speculation_window = renderer_->last_stats().window;
  r.queue_ms = ms_between(job.pose.received, t_start);
  // Render time includes the plane download (GPU) but not the conversion itself.
  r.render_ms = std::max(0.0, ms_between(t_start, Clock::now()) - r.convert_ms);
}

Session::Rendered Session::run_render(Job job, std::unique_ptr<Yuv420Image> planes) {
  Rendered r;
  r.job = std::move(job);
  r.planes = std::move(planes);
  if (gone_) {  // nobody to send it to: the lane moves on to the next session at once
    r.error = "session gone";
    return r;
  }
  try {
    render_into(r.job, r.planes->target(r.job.width, r.job.height), r);
  } catch (const RenderBudgetError& e) {
    r.error = e.what();
    r.over_budget = true;
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  return r;
}

void Session::ensure_encoder(const Job& job, bool& idr) {
  const EncoderPolicy& policy = shared_.options.encoder_policy;
  const int live = static_cast<int>(std::max<std::int64_t>(1, shared_.metrics.sessions_open.load()));
  const auto now = Clock::now();
  // The link's cap follows the link frame by frame: x264 takes a new VBV rate without an IDR.
  if (encoder_ && encoder_->width() == job.width && encoder_->height() == job.height &&
      encoder_bitrate_kbps_ == job.max_bitrate_kbps && encoder_link_kbps_ != job.link_kbps) {
    const int client = job.max_bitrate_kbps;
    const int cap = job.link_kbps > 0 && client > 0 ? std::min(client, job.link_kbps) : std::max(client, job.link_kbps);
    const int rate = target_bitrate_kbps(policy, job.width, job.height, kStreamFps, cap);
    if (rate > 0 && encoder_->set_max_bitrate_kbps(rate)) encoder_link_kbps_ = job.link_kbps;
  }
  if (encoder_ && encoder_->width() == job.width && encoder_->height() == job.height &&
      encoder_bitrate_kbps_ == job.max_bitrate_kbps && encoder_link_kbps_ == job.link_kbps) {
    // The same stream: rebuilt only for a new share of the cores (x264's threads are fixed
    // when it opens; NVENC has none to share).
    const int wanted = encoder_threads(policy, job.width, job.height, live);
    if (encoder_->name() == "nvenc" || !should_rebuild(encoder_threads_, wanted, now - encoder_built_)) return;
    shared_.metrics.encoder_rebuilds_total++;
  }
  // A client's Quality and the link's cap both lower the policy's rate, never raise it.
  const int client = job.max_bitrate_kbps;
  const int cap = job.link_kbps > 0 && client > 0 ? std::min(client, job.link_kbps) : std::max(client, job.link_kbps);
  EncoderConfig cfg = encoder_config(policy, job.width, job.height, kStreamFps, live, cap);
  // One-job path: a GPU frame goes to NVENC as a CUDA frame (no host copy); x264 ignores it.
  cfg.device_input = !pipelined_ && renderer_->name() == "cuda";
  cfg.cuda_device = std::max(gpu_, 0);
  // The requested kind: "auto" reuses the process's NVENC probe and may fall back per session.
  bool fell_back = false;
  encoder_ = make_encoder(shared_.options.encoder, cfg, nullptr, &fell_back);
  encoder_bitrate_kbps_ = job.max_bitrate_kbps;
  encoder_link_kbps_ = job.link_kbps;
  encoder_threads_ = cfg.threads;
  encoder_built_ = now;
  if (fell_back) shared_.metrics.encoder_fallbacks_total++;
  idr = true;
}

Session::JobResult Session::run_encode(Rendered& frame) {
  try {
    bool idr = frame.job.force_idr;
    ensure_encoder(frame.job, idr);
    const EncodedFrame enc = encoder_->encode_yuv420(frame.planes->planes(), idr);
    return frame_message(frame.job, enc, frame);
  } catch (const std::exception& e) {
    JobResult r;
    r.error = e.what();
    return r;
  }
}

Session::JobResult Session::run_render_and_encode(const Job& job) {
  if (gone_) {
    JobResult r;
    r.error = "session gone";
    return r;
  }
  try {
    bool idr = job.force_idr;
    ensure_encoder(job, idr);
    Rendered r;
    // Straight into the encoder's input planes: the hw frame's device memory for NVENC.
    render_into(job, encoder_->input_target(), r);
    return frame_message(job, encoder_->encode_input(idr), r);
  } catch (const RenderBudgetError& e) {
    JobResult r;
    r.error = e.what();
    r.over_budget = true;
    return r;
  } catch (const std::exception& e) {
    JobResult r;
    r.error = e.what();
    return r;
  }
}

Session::JobResult Session::frame_message(const Job& job, const EncodedFrame& enc, const Rendered& rendered) {
  JobResult r;
  pb::ServerMessage m;
  pb::Frame* f = m.mutable_frame();
  f->set_sequence(job.frame_sequence);
  f->set_pose_sequence(job.pose.sequence);
  f->set_client_time_ms(job.pose.client_time_ms);
  f->set_key_frame(enc.key_frame);
  f->set_width(static_cast<std::uint32_t>(job.width));
  f->set_height(static_cast<std::uint32_t>(job.height));
  f->set_payload(enc.data.data(), enc.data.size());
  r.render_key_frame = rendered.render_key_frame;
  r.speculation_window = rendered.speculation_window;
  r.queue_ms = rendered.queue_ms;
  r.render_ms = rendered.render_ms;
  r.convert_ms = rendered.convert_ms;
  r.encode_ms = enc.encode_ms;
  pb::FrameTimings* t = f->mutable_timings();
  t->set_queue_ms(r.queue_ms);
  t->set_render_ms(r.render_ms);
  t->set_convert_ms(r.convert_ms);
  t->set_encode_ms(r.encode_ms);
  t->set_render_key_frame(r.render_key_frame);
  t->set_speculation_window(static_cast<std::uint32_t>(std::max(0, r.speculation_window)));
  t->set_previous_send_ms(job.previous_send_ms);
  r.total_ms = ms_between(job.pose.received, Clock::now());
  r.quality_level = job.quality_level;
  r.refine = job.pose.full_size;
  t->set_total_ms(r.total_ms);
  m.SerializeToString(&r.message);
  r.key_frame = enc.key_frame;
  r.payload_bytes = enc.data.size();
  return r;
}

void Session::on_job_done(JobResult result) {
  if (state_ != State::open || result.message.empty()) shared_.metrics.dropped_frames_total++;
  if (state_ != State::open) return;
  // A view whose render list the renderer refused (RenderListBudget: a scene of giant Gaussians,
  // say) is the request's fault, not the server's: INVALID_ARGUMENT with the rule's message, so
  // that a client can tell it from a failure, and a counter for the operator.
  if (result.message.empty() && result.over_budget) {
    shared_.metrics.render_budget_refusals_total++;
    return fail(pb::ERROR_INVALID_ARGUMENT,
                "this view cannot be rendered: " + result.error + " (a smaller viewport or another view may fit)");
  }
  if (result.message.empty()) return fail(pb::ERROR_INTERNAL, "render/encode failed: " + result.error);
  pacing_.on_encode(result.encode_ms);
  if (in_flight_ == 0) last_progress_ = Clock::now();  // the slow-reader clock starts now
  in_flight_++;
  frames_sent_++;
  frames_since_stats_++;
  bytes_since_stats_ += result.payload_bytes;
  render_ms_sum_ += result.render_ms;
  encode_ms_sum_ += result.encode_ms;
  if (result.key_frame) key_frames_++;
  if (result.render_key_frame)
    render_key_frames_++;
  else
    render_sub_frames_++;
  ServerMetrics& m = shared_.metrics;
  m.frames_total++;
  m.bytes_total += result.payload_bytes;
  if (result.key_frame) m.key_frames_total++;
  (result.render_key_frame ? m.render_key_frames_total : m.render_sub_frames_total)++;
  m.queue_seconds.observe(result.queue_ms / 1000.0);
  (result.render_key_frame ? m.render_key_seconds : m.render_sub_seconds).observe(result.render_ms / 1000.0);
  if (gpu_ >= 0) m.observe_gpu_render(gpu_, result.render_ms / 1000.0);
  m.convert_seconds.observe(result.convert_ms / 1000.0);
  m.encode_seconds.observe(result.encode_ms / 1000.0);
  m.speculation_window.observe(result.speculation_window);
  if (shared_.options.adaptive_quality) {
    if (!result.refine) quality_.on_frame(result.quality_level, result.total_ms);
    last_frame_level_ = result.quality_level;
  }
  handed_.push_back({Clock::now(), result.message.size()});
  shared_.transport.send(id_, std::move(result.message), /*counted=*/true);
  maybe_start_render();
}

void Session::on_link_sample(const Handed& frame, Clock::time_point written, const SocketSample& socket) {
  if (!shared_.options.link_control) return;
  const bool was_limited = link_.limited();
  const int cuts = link_.decreases();
  link_.on_written(frame.bytes, frame.at, written, socket, link_ceiling_kbps_);
  ServerMetrics& m = shared_.metrics;
  m.link_rate_decreases_total += static_cast<std::uint64_t>(link_.decreases() - cuts);
  if (link_.limited() != was_limited) m.sessions_link_limited += link_.limited() ? 1 : -1;
  // The kernel's buffer sized by the link: TCP can never put much more than it in front of the
  // link, whatever the controller's estimate, so a link that drops suddenly finds little in
  // flight. It holds a tenth of a second or two round trips, whichever is longer (TCP needs a
  // round trip's worth in flight to keep up), of the link's rate while the link limits, else of
  // the policy's rate (the most the stream may need; not the measured rate, which a small buffer
  // would itself hold down on a long round trip). At least 2 KiB while limiting, 8 KiB otherwise;
  // the configured size caps it, and is kept for a stream without a policy rate (crf alone).
  const int configured = shared_.options.socket_send_buffer;
  const double rate_kbps = link_.limited() ? link_.link_kbps() : link_ceiling_kbps_;
  const double seconds = std::max(0.1, 2.0 * link_.min_rtt_ms() / 1000.0);
  const double floor_bytes = link_.limited() ? 2048 : 8192;  // the kernel keeps about 4.6 KB at least
  const int wanted = rate_kbps > 0 && configured > 0
                         ? static_cast<int>(std::clamp(rate_kbps * 1000.0 / 8.0 * seconds,
                                                       std::min<double>(floor_bytes, configured), double(configured)))
                         : configured;
  // Set when it moves by over a quarter (or back to the configured size).
  if (wanted > 0 && wanted != send_buffer_ &&
      (send_buffer_ == 0 || wanted == configured || std::abs(wanted - send_buffer_) > send_buffer_ / 4)) {
    shared_.transport.set_send_buffer(id_, wanted);
    send_buffer_ = wanted;
  }
  if (!shared_.options.adaptive_quality) return;
  // The floor of this level's size and whether the cap would carry the level above.
  const int level = quality_.level();
  const int cap = link_.cap_kbps(link_ceiling_kbps_);
  const int here =
      link_floor_kbps(AdaptiveQuality::scaled_side(width_, level), AdaptiveQuality::scaled_side(height_, level));
  const int above = level > 0 ? link_floor_kbps(AdaptiveQuality::scaled_side(width_, level - 1),
                                                AdaptiveQuality::scaled_side(height_, level - 1))
                              : 0;
  quality_.on_link(link_.limited(), link_.limited() && cap < here, !link_.limited() || cap >= 2 * above);
}

void Session::adapt_quality(Clock::time_point now) {
  const int step = quality_.on_tick(now);
  if (step != 0) (step > 0 ? shared_.metrics.quality_up_total : shared_.metrics.quality_down_total)++;
  // The camera stopped on a reduced frame: its pose once more at full size.
  if (!pending_ && last_started_ && quality_.take_refine(now, last_frame_level_)) {
    pending_ = last_started_;
    pending_->full_size = true;
    pending_->received = now;
    shared_.metrics.refine_frames_total++;
    maybe_start_render();
  }
}

}  // namespace catgs::server
