// A session's stream (session_stream.h): the frame's way, stage by stage, and what the written
// frames and the client's receipts say about the link (link_rate.h) and the session's size
// (adaptive_quality.h).
#include "session/session_stream.h"

#include <boost/asio/post.hpp>

#include <algorithm>
#include <cstdlib>

#include "encode/frame_encoding.h"

namespace catgs::server {

SessionStream::SessionStream(SessionShared& shared, ConnId id, SessionOwner& owner)
    : shared_(shared),
      id_(id),
      owner_(owner),
      frames_(shared.settings.frame, shared.metrics),
      pacing_(shared.settings.frame.frame_deadline_slots) {}

SessionStream::~SessionStream() {
  if (link_.limited()) shared_.metrics.sessions_link_limited--;
}

void SessionStream::open(std::unique_ptr<Renderer> renderer, std::shared_ptr<const GaussianModel> model, int gpu,
                         bool pipelined, bool av1_ok, std::shared_ptr<ContentRates> content_rates) {
  gpu_ = gpu;
  frames_.open(std::move(renderer), std::move(model), gpu, pipelined, av1_ok, std::move(content_rates));
}

bool SessionStream::first_frame_av1(int live_sessions) const {
  FramePipeline::JobShape first;
  first.width = width_;
  first.height = height_;
  return frames_.stream_is_av1(first, live_sessions);
}

void SessionStream::set_viewport(int width, int height) {
  width_ = width;
  height_ = height;
  frames_.request_idr();  // the encoder is rebuilt at the new size; its first frame is an IDR
}

void SessionStream::set_max_bitrate(int kbps) {
  max_bitrate_kbps_ = kbps;
  frames_.request_idr();  // the encoder is rebuilt with it; its first frame is an IDR
}

void SessionStream::on_pose(const pb::Pose& pose, const CameraPose& cam, const std::optional<StereoPose>& eyes,
                            Clock::time_point received) {
  poses_received_++;
  shared_.metrics.poses_total++;
  // The client's own end-to-end measurement of an earlier frame (0: nothing new).
  if (pose.shown_latency_ms() > 0) {
    shared_.metrics.pose_to_frame_seconds.observe(pose.shown_latency_ms() / 1000.0);
    if (shared_.settings.frame.adaptive_quality) quality_.on_latency(received, pose.shown_latency_ms());
  }
  if (pose.received_ms() > 0) on_receipt(pose.received_frame_sequence(), pose.received_ms(), received);
  const bool replaced = frames_.pending().has_value();
  if (replaced) {
    poses_skipped_++;                       // latest pose wins: the older one is never rendered
    shared_.metrics.poses_skipped_total++;  // a skip, not a drop: the newer pose is rendered instead
  }
  if (shared_.settings.frame.adaptive_quality) quality_.on_pose(received, replaced);
  still_.on_pose(received);
  pacing_.on_pose(received);
  FramePipeline::PendingPose next;
  next.pose = next.sent = cam;
  next.sequence = pose.sequence();
  next.client_time_ms = pose.client_time_ms();
  next.received = received;
  next.eyes = eyes;
  display_hz_ = pose.display_hz();  // the encoder takes it at its next build
  if (shared_.settings.frame.pose_prediction && !eyes) {
    prediction_.on_pose(cam, pose.client_time_ms(), pose.shown_latency_ms(), pose.display_hz());
    next.pose = prediction_.predicted();
    next.predicted = next.pose.position != cam.position || next.pose.orientation != cam.orientation;
  }
  frames_.offer(next);
  admit();
}

// --- the stages ---

void SessionStream::admit() {
  // Frames admitted but not yet written: those the transport holds and the one being encoded.
  const int admitted = in_flight_ + (frames_.encoding() ? 1 : 0);
  const FrameSettings& fs = shared_.settings.frame;
  if (!owner_.is_open() || admitted >= fs.max_frames_in_flight || !frames_.can_start_render()) return;
  // Adaptive quality scales the size (a refine frame is full size); a new size is an IDR.
  FramePipeline::JobShape shape;
  shape.quality_level = fs.adaptive_quality && !frames_.pending()->refine ? quality_.level() : 0;
  shape.width = AdaptiveQuality::scaled_side(width_, shape.quality_level);
  shape.height = AdaptiveQuality::scaled_side(height_, shape.quality_level);
  // A headset's frame holds two eyes of an even width each (I420's chroma pairs columns).
  if (frames_.pending()->eyes) shape.width -= shape.width % 4;
  shape.max_bitrate_kbps = max_bitrate_kbps_;
  shape.previous_send_ms = last_send_ms_;
  shape.fps = display_hz_ > 0 ? static_cast<int>(std::lround(display_hz_)) : kStreamFps;
  shape.link = link_inputs();  // read again at its encode
  shape.link_read_at = Clock::now();
  FramePipeline::StartedRender started = frames_.start_render(shape);
  const std::int64_t pixels = static_cast<std::int64_t>(shape.width) * shape.height;
  if (!frames_.pipelined()) {
    shared_.renders.post(id_, pixels,
                         [keep = owner_.keep_alive(), this, job = std::move(started.job)] { render_and_encode(job); });
    return;
  }
  shared_.renders.post(id_, pixels, [keep = owner_.keep_alive(), this, started = std::move(started)]() mutable {
    return render(std::move(started));
  });
}

RenderScheduler::Finish SessionStream::render(FramePipeline::StartedRender started) {
  FramePipeline::Rendered frame =
      frames_.begin_render(std::move(started.job), std::move(started.planes), owner_.gone());
  // The lane finishes the frame when it holds its most frames in flight or has nothing to start
  // (render_scheduler.h "Frames in flight"); this session's next render waits for rendered().
  const bool begun = frame.render_begun;
  return RenderScheduler::Finish::of(
      [keep = owner_.keep_alive(), this, frame = std::move(frame)]() mutable {
        frames_.finish_render(frame);
        boost::asio::post(owner_.strand(),
                          [keep, this, frame = std::move(frame)]() mutable { rendered(std::move(frame)); });
      },
      [this, begun] { return !begun || frames_.frame_ready(); });
}

void SessionStream::rendered(FramePipeline::Rendered frame) {
  frames_.end_render();
  if (!frame.record.error.empty()) return hand_off(frames_.take_failed(std::move(frame)));
  owner_.on_frame_buffers(frame.record.buffer_bytes, frame.record.buffer_shape);
  pacing_.on_rendered(frame.record.queue_ms + frame.record.render_ms + frame.record.convert_ms);
  frames_.store_rendered(std::move(frame));
  start_encode();
  admit();
}

void SessionStream::start_encode() {
  if (frames_.encoding() || !frames_.rendered()) return;
  if (!owner_.is_open()) {  // nobody to send it to
    frames_.drop_rendered();
    shared_.metrics.dropped_frames_total++;
    return;
  }
  // Past its display slot with a newer pose waiting: the encoder's time goes to the newer pose.
  // A refine frame (still_refine.h) or a forced IDR is never skipped: nothing else carries it.
  const FramePipeline::Job& job = frames_.rendered()->job;
  if (!job.pose.refine && !job.force_idr &&
      pacing_.skip_before_encode(job.pose.received, Clock::now(), frames_.pending().has_value())) {
    frames_.drop_rendered();
    poses_skipped_++;
    shared_.metrics.deadline_skips_total++;
    admit();
    return;
  }
  std::shared_ptr<FramePipeline::Rendered> frame = frames_.start_encode();
  // The link's cap as it stands now, not when the render started: a cut must reach the next
  // frame encoded, not one a render later (a frame's time on a slow link).
  frame->job.shape.link = link_inputs();
  frame->job.shape.link_read_at = Clock::now();
  boost::asio::post(shared_.io, [keep = owner_.keep_alive(), this, frame] { encode(frame); });
}

void SessionStream::encode(const std::shared_ptr<FramePipeline::Rendered>& frame) {
  JobResult result = frames_.encode(*frame);
  boost::asio::post(owner_.strand(), [keep = owner_.keep_alive(), this, frame, result = std::move(result)]() mutable {
    frames_.end_encode(*frame);
    hand_off(std::move(result));
    start_encode();
    admit();  // the rendered slot may have just been freed
  });
}

void SessionStream::render_and_encode(const FramePipeline::Job& job) {
  JobResult result = frames_.render_and_encode(job, owner_.gone());
  boost::asio::post(owner_.strand(), [keep = owner_.keep_alive(), this, result = std::move(result)]() mutable {
    frames_.end_render();
    hand_off(std::move(result));
  });
}

void SessionStream::hand_off(JobResult result) {
  if (!owner_.is_open() || result.message.empty()) shared_.metrics.dropped_frames_total++;
  if (!owner_.is_open()) return;
  if (!result.message.empty()) link_ceiling_kbps_ = result.link_ceiling_kbps;
  owner_.on_frame_buffers(result.record.buffer_bytes, result.record.buffer_shape);
  if (result.message.empty() && result.record.out_of_memory)
    return owner_.on_out_of_memory(result.record.error, ++out_of_memory_streak_);
  if (!result.message.empty()) out_of_memory_streak_ = 0;
  // A view whose render list the renderer refused (RenderListBudget: a scene of giant Gaussians,
  // say) is the request's fault, not the server's: INVALID_ARGUMENT with the rule's message, so
  // that a client can tell it from a failure, and a counter for the operator.
  if (result.message.empty() && result.record.over_budget) {
    shared_.metrics.render_budget_refusals_total++;
    return owner_.end_session(pb::ERROR_INVALID_ARGUMENT, "this view cannot be rendered: " + result.record.error +
                                                              " (a smaller viewport or another view may fit)");
  }
  if (result.message.empty())
    return owner_.end_session(pb::ERROR_INTERNAL, "render/encode failed: " + result.record.error);
  pacing_.on_encode(result.encode_ms);
  if (in_flight_ == 0) last_progress_ = Clock::now();  // the slow-reader clock starts now
  in_flight_++;
  count(result);
  if (shared_.settings.frame.adaptive_quality && !result.refine)
    quality_.on_frame(result.quality_level, result.total_ms);
  // A predicted frame is held back too: its pose ran ahead of a camera that may have stopped, and
  // the stop's refine frame draws the client's own pose.
  still_.on_frame(result.quality_level > 0 || result.rate_capped || result.predicted, result.refine,
                  result.refine_vbv_bound);
  handed_.push_back({Clock::now(), result.message.size(), result.frame_sequence, result.link_read_at, result.refine});
  recent_.push_back(handed_.back());
  if (recent_.size() > kRecentFrames) recent_.pop_front();
  shared_.transport.send(id_, std::move(result.message), /*counted=*/true);
  admit();
}

void SessionStream::count(const JobResult& result) {
  frames_sent_++;
  frames_since_stats_++;
  bytes_since_stats_ += result.payload_bytes;
  render_ms_sum_ += result.record.render_ms;
  encode_ms_sum_ += result.encode_ms;
  if (result.encode_psnr_db > 0) {
    encode_psnr_sum_ += result.encode_psnr_db;
    encode_psnr_frames_++;
  }
  encoder_ = result.encoder;
  lod_error_px_sum_ += result.record.lod_error_px;
  splats_sum_ += static_cast<double>(result.record.frame.visible);
  if (result.record.memory_fallback > 0) {
    memory_fallbacks_++;
    memory_note_ = result.record.memory_note;
  }
  if (result.key_frame) key_frames_++;
  if (result.record.frame.key_frame)
    render_key_frames_++;
  else
    render_sub_frames_++;
  ServerMetrics& m = shared_.metrics;
  m.frames_total++;
  m.bytes_total += result.payload_bytes;
  if (result.key_frame) m.key_frames_total++;
  (result.record.frame.key_frame ? m.render_key_frames_total : m.render_sub_frames_total)++;
  if (result.record.frame.subframe_rejected) m.render_rekeys_total++;
  if (result.record.frame.predicted_gain > 0) m.speculation_predicted_gain.observe(result.record.frame.predicted_gain);
  if (result.record.frame.measured_gain > 0) m.speculation_measured_gain.observe(result.record.frame.measured_gain);
  m.queue_seconds.observe(result.record.queue_ms / 1000.0);
  (result.record.frame.key_frame ? m.render_key_seconds : m.render_sub_seconds)
      .observe(result.record.render_ms / 1000.0);
  if (gpu_ >= 0) m.observe_gpu_render(gpu_, result.record.render_ms / 1000.0);
  m.convert_seconds.observe(result.record.convert_ms / 1000.0);
  m.encode_seconds.observe(result.encode_ms / 1000.0);
  if (result.encode_psnr_db > 0) m.encode_psnr_db.observe(result.encode_psnr_db);
  m.speculation_window.observe(result.record.frame.window);
  m.frame_lod_bound_px.observe(result.record.lod_error_px);
}

void SessionStream::on_sent(Clock::time_point written, const SocketSample& socket) {
  if (in_flight_ > 0) in_flight_--;
  last_progress_ = Clock::now();
  if (!handed_.empty()) {  // frames are written in the order they were queued
    const Handed frame = handed_.front();
    last_send_ms_ = ms_between(frame.at, written);
    handed_.pop_front();
    // The receipts' delays count from here (link_rate.h Receipt::sent).
    for (auto it = recent_.rbegin(); it != recent_.rend(); ++it)
      if (it->sequence == frame.sequence) {
        it->written = written;
        break;
      }
    shared_.metrics.send_seconds.observe(last_send_ms_ / 1000.0);
    on_link_sample(frame, written, socket);
  }
  admit();
}

bool SessionStream::unread_for(Clock::time_point now, std::chrono::milliseconds timeout) const {
  return in_flight_ > 0 && now - last_progress_ > timeout;
}

void SessionStream::fill_stats(pb::Stats& s, double seconds) {
  s.set_frames_sent(frames_sent_);
  s.set_poses_received(poses_received_);
  s.set_poses_skipped(poses_skipped_);
  const double n = frames_since_stats_ ? frames_since_stats_ : 1;
  s.set_render_ms_mean(render_ms_sum_ / n);
  s.set_encode_ms_mean(encode_ms_sum_ / n);
  if (encode_psnr_frames_ > 0) s.set_encode_psnr_db_mean(encode_psnr_sum_ / encode_psnr_frames_);
  s.set_encoder(encoder_);
  s.set_lod_error_px_mean(lod_error_px_sum_ / n);
  s.set_splats_mean(splats_sum_ / n);
  s.set_memory_fallback_frames(memory_fallbacks_);
  s.set_memory_note(memory_note_);
  memory_fallbacks_ = 0;
  memory_note_.clear();
  s.set_bytes_per_second(static_cast<double>(bytes_since_stats_) / seconds);
  s.set_link_kbps(link_.link_kbps());
  s.set_rtt_ms(link_.rtt_ms());
  if (link_.limited()) s.set_bitrate_cap_kbps(static_cast<std::uint32_t>(link_.cap_kbps(link_ceiling_kbps_)));
  s.set_quality_level(static_cast<std::uint32_t>(shared_.settings.frame.adaptive_quality ? quality_.level() : 0));
  s.set_key_frames(render_key_frames_);
  s.set_sub_frames(render_sub_frames_);
  // A still camera sends no poses and gets no frames: an idle interval has no frame rate to add.
  if (frames_since_stats_ > 0) shared_.metrics.session_fps.observe(frames_since_stats_ / seconds);
  frames_since_stats_ = 0;
  bytes_since_stats_ = 0;
  render_ms_sum_ = encode_ms_sum_ = encode_psnr_sum_ = lod_error_px_sum_ = splats_sum_ = 0;
  encode_psnr_frames_ = 0;
}

void SessionStream::on_tick(Clock::time_point now) {
  if (shared_.settings.frame.adaptive_quality) {
    const int step = quality_.on_tick(now);
    if (step != 0) (step > 0 ? shared_.metrics.quality_up_total : shared_.metrics.quality_down_total)++;
  }
  // The camera stopped on a frame held back (smaller, or under a rate cap): its pose once more,
  // at full size and the stream's crf.
  if (shared_.settings.frame.still_refine && frames_.can_refine() && still_.take(now)) {
    frames_.refine(now);
    shared_.metrics.refine_frames_total++;
    admit();
  }
}

// --- the link ---

LinkInputs SessionStream::link_inputs() const {
  // The link as it stands now (frame_encoding turns it into the frame's cap, encode/frame_encoding.h).
  LinkInputs in;
  in.limiting = shared_.settings.frame.link_control && link_.limited();
  in.cap_kbps = link_.cap_kbps(0);  // before the stream's ceiling, which frame_encoding applies
  in.encoder_gain = link_.encoder_gain();
  in.frame_rate = link_.frame_rate();
  return in;
}

void SessionStream::on_link_sample(const Handed& frame, Clock::time_point written, const SocketSample& socket) {
  // A refine frame is sent once, larger than the moving stream's share of the link: its time on
  // the wire is its size, not a queue (still_refine.h).
  if (!shared_.settings.frame.link_control || frame.refine) return;
  const bool was_limited = link_.limited();
  const int cuts = link_.decreases();
  link_.on_written(frame.bytes, frame.at, written, socket, link_ceiling_kbps_);
  after_link_update(was_limited, cuts);
}

void SessionStream::after_link_update(bool was_limited, int cuts) {
  ServerMetrics& m = shared_.metrics;
  m.link_rate_decreases_total += static_cast<std::uint64_t>(link_.decreases() - cuts);
  for (int c = 0; c < LinkRate::kCauses; ++c) {
    const int now = link_.decreases(static_cast<LinkRate::Cause>(c));
    m.link_rate_cuts_total[c] += static_cast<std::uint64_t>(now - cuts_by_cause_[c]);
    cuts_by_cause_[c] = now;
  }
  if (link_.limited() != was_limited) m.sessions_link_limited += link_.limited() ? 1 : -1;
  // The kernel's buffer sized by the link: TCP can never put much more than it in front of the
  // link, whatever the controller's estimate, so a link that drops suddenly finds little in
  // flight. It holds a tenth of a second or two round trips, whichever is longer (TCP needs a
  // round trip's worth in flight to keep up), of the link's rate while the link limits, else of
  // the policy's rate (the most the stream may need; not the measured rate, which a small buffer
  // would itself hold down on a long round trip). At least 2 KiB while limiting, 8 KiB otherwise;
  // the configured size caps it, and is kept for a stream without a policy rate (crf alone).
  const int configured = shared_.settings.frame.socket_send_buffer;
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
  if (!shared_.settings.frame.adaptive_quality) return;
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

void SessionStream::on_receipt(std::uint32_t sequence, double received_ms, Clock::time_point now) {
  if (!shared_.settings.frame.link_control || sequence == last_receipt_) return;
  // Frames go out in sequence order; a receipt for one no longer in the window says nothing new.
  for (auto it = recent_.rbegin(); it != recent_.rend(); ++it) {
    if (it->sequence != sequence) continue;
    last_receipt_ = sequence;
    if (it->refine) return;  // its arrival is its own size on the wire (on_link_sample)
    shared_.metrics.frame_receipts_total++;
    const bool was_limited = link_.limited();
    const int cuts = link_.decreases();
    const Clock::time_point sent = it->written != Clock::time_point{} ? it->written : it->at;
    link_.on_receipt({sequence, it->bytes, sent, it->rate_at, received_ms}, now, link_ceiling_kbps_);
    return after_link_update(was_limited, cuts);
  }
}

}  // namespace catgs::server
