// A session's stream (session.h): when the frame pipeline's stages may start (frame_pipeline.h;
// latest pose wins, frames in flight, a rendered frame that would miss its display slot is
// skipped before its encode: frame_pacing.h), the jobs posted to the render lanes and the worker
// pool, each finished Frame handed to the transport and counted, and what the written frames
// say about the link (link_rate.h) and the session's size (adaptive_quality.h). The protocol
// state machine that feeds it is session.cpp.
#include "session/session.h"

#include <boost/asio/post.hpp>

#include <algorithm>

#include "encode/encoder_policy.h"
#include "session/link_rate.h"

namespace catgs::server {

void Session::maybe_start_render() {
  // Frames admitted but not yet written: those the transport holds and the one being encoded.
  const int admitted = in_flight_ + (frames_.encoding() ? 1 : 0);
  const FrameSettings& fs = shared_.settings.frame;
  if (state_ != State::open || admitted >= fs.max_frames_in_flight || !frames_.can_start_render()) return;
  // Adaptive quality scales the size (a refine frame is full size); a new size is an IDR.
  FramePipeline::JobShape shape;
  shape.quality_level = fs.adaptive_quality && !frames_.pending()->refine ? quality_.level() : 0;
  shape.width = AdaptiveQuality::scaled_side(width_, shape.quality_level);
  shape.height = AdaptiveQuality::scaled_side(height_, shape.quality_level);
  shape.max_bitrate_kbps = max_bitrate_kbps_;
  shape.previous_send_ms = last_send_ms_;
  shape.link_kbps = link_vbv_kbps(shape.width, shape.height);  // set again at its encode
  shape.link_read_at = Clock::now();
  FramePipeline::StartedRender started = frames_.start_render(shape);
  const std::int64_t pixels = static_cast<std::int64_t>(shape.width) * shape.height;
  // The job holds this session, so the renderer it offers lives while the job is queued.
  std::optional<RenderScheduler::Stage1Share> share = frames_.stage1_share(started.job);
  if (!frames_.pipelined()) {
    shared_.renders.post(
        id_, pixels,
        [self = shared_from_this(), job = std::move(started.job)] {
          JobResult result = self->frames_.render_and_encode(job, self->gone_);
          boost::asio::post(self->strand_, [self, result = std::move(result)]() mutable {
            self->frames_.end_render();
            self->on_job_done(std::move(result));
          });
        },
        std::move(share));
    return;
  }
  shared_.renders.post(
      id_, pixels,
      [self = shared_from_this(), started = std::move(started)]() mutable {
        FramePipeline::Rendered frame =
            self->frames_.render(std::move(started.job), std::move(started.planes), self->gone_);
        boost::asio::post(self->strand_, [self, frame = std::move(frame)]() mutable {
          self->frames_.end_render();
          if (!frame.error.empty()) return self->on_job_done(self->frames_.take_failed(std::move(frame)));
          self->update_memory(frame.buffer_bytes);
          self->pacing_.on_rendered(frame.queue_ms + frame.render_ms + frame.convert_ms);
          self->frames_.store_rendered(std::move(frame));
          self->maybe_start_encode();
          self->maybe_start_render();
        });
      },
      std::move(share));
}

int Session::link_vbv_kbps(int width, int height) {
  // The link's cap against the policy's rate at this size (link_rate.h), both in bits a second
  // on the wire: the VBV's rate is per frame at the nominal kStreamFps, so a stream at fewer
  // frames a second sends that share of it. At least 10 frames a second's share: frames written
  // slowly because the link is jammed must not each get a larger share of the cap (a frame of
  // half a second on the wire at 2 frames/s makes the jam worse).
  const double fps_share = std::clamp(link_.frame_rate() / kStreamFps, 10.0 / kStreamFps, 1.0);
  const int vbv_ceiling = frames_.policy_bitrate_kbps(width, height, kStreamFps, max_bitrate_kbps_);
  link_ceiling_kbps_ = vbv_ceiling > 0 ? std::max(1, static_cast<int>(vbv_ceiling * fps_share)) : 0;
  if (!shared_.settings.frame.link_control || !link_.limited()) return 0;
  return std::max(1, static_cast<int>(link_.cap_kbps(link_ceiling_kbps_) * link_.encoder_gain() / fps_share));
}

void Session::maybe_start_encode() {
  if (frames_.encoding() || !frames_.rendered()) return;
  if (state_ != State::open) {  // nobody to send it to
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
    maybe_start_render();
    return;
  }
  std::shared_ptr<FramePipeline::Rendered> frame = frames_.start_encode();
  // The link's cap as it stands now, not when the render started: a cut must reach the next
  // frame encoded, not one a render later (a frame's time on a slow link).
  frame->job.shape.link_kbps = link_vbv_kbps(frame->job.shape.width, frame->job.shape.height);
  frame->job.shape.link_read_at = Clock::now();
  boost::asio::post(shared_.io, [self = shared_from_this(), frame] {
    JobResult result = self->frames_.encode(*frame);
    boost::asio::post(self->strand_, [self, frame, result = std::move(result)]() mutable {
      self->frames_.end_encode(*frame);
      self->on_job_done(std::move(result));
      self->maybe_start_encode();
      self->maybe_start_render();  // the rendered slot may have just been freed
    });
  });
}

void Session::on_job_done(JobResult result) {
  if (state_ != State::open || result.message.empty()) shared_.metrics.dropped_frames_total++;
  if (state_ != State::open) return;
  update_memory(result.buffer_bytes);
  if (result.message.empty() && result.out_of_memory) return on_out_of_memory(result.error);
  if (!result.message.empty()) out_of_memory_streak_ = 0;
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
  lod_error_px_sum_ += result.lod_error_px;
  splats_sum_ += static_cast<double>(result.splats);
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
  if (result.render_rekey) m.render_rekeys_total++;
  if (result.stage1_views > 1) m.stage1_shared_frames_total++;
  if (result.predicted_gain > 0) m.speculation_predicted_gain.observe(result.predicted_gain);
  if (result.measured_gain > 0) m.speculation_measured_gain.observe(result.measured_gain);
  m.queue_seconds.observe(result.queue_ms / 1000.0);
  (result.render_key_frame ? m.render_key_seconds : m.render_sub_seconds).observe(result.render_ms / 1000.0);
  if (gpu_ >= 0) m.observe_gpu_render(gpu_, result.render_ms / 1000.0);
  m.convert_seconds.observe(result.convert_ms / 1000.0);
  m.encode_seconds.observe(result.encode_ms / 1000.0);
  m.speculation_window.observe(result.speculation_window);
  if (shared_.settings.frame.adaptive_quality && !result.refine)
    quality_.on_frame(result.quality_level, result.total_ms);
  still_.on_frame(result.quality_level > 0 || result.rate_capped, result.refine, result.refine_vbv_bound);
  handed_.push_back({Clock::now(), result.message.size(), result.frame_sequence, result.link_read_at, result.refine});
  recent_.push_back(handed_.back());
  if (recent_.size() > kRecentFrames) recent_.pop_front();
  shared_.transport.send(id_, std::move(result.message), /*counted=*/true);
  maybe_start_render();
}

void Session::on_link_sample(const Handed& frame, Clock::time_point written, const SocketSample& socket) {
  // A refine frame is sent once, larger than the moving stream's share of the link: its time on
  // the wire is its size, not a queue (still_refine.h).
  if (!shared_.settings.frame.link_control || frame.refine) return;
  const bool was_limited = link_.limited();
  const int cuts = link_.decreases();
  link_.on_written(frame.bytes, frame.at, written, socket, link_ceiling_kbps_);
  after_link_update(was_limited, cuts);
}

void Session::after_link_update(bool was_limited, int cuts) {
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

void Session::on_receipt(std::uint32_t sequence, double received_ms, Clock::time_point now) {
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

void Session::adapt_quality(Clock::time_point now) {
  const int step = quality_.on_tick(now);
  if (step != 0) (step > 0 ? shared_.metrics.quality_up_total : shared_.metrics.quality_down_total)++;
}

void Session::refine_still_view(Clock::time_point now) {
  // The camera stopped on a frame held back (smaller, or under a rate cap): its pose once more,
  // at full size and the stream's crf.
  if (!frames_.can_refine() || !still_.take(now)) return;
  frames_.refine(now);
  shared_.metrics.refine_frames_total++;
  maybe_start_render();
}

}  // namespace catgs::server
