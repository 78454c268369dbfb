// The per-session rate controller (link_rate.h).
#include "session/link_rate.h"

#include <algorithm>
#include <cmath>

namespace catgs::server {

namespace {

constexpr double kAverageWeight = 0.25;  // of the newest sample in the exponential averages

double ms_between(LinkRate::Clock::time_point a, LinkRate::Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}
double average(double mean, double sample) { return mean > 0 ? mean + kAverageWeight * (sample - mean) : sample; }

}  // namespace

int link_floor_kbps(int width, int height) {
  return std::max(30, static_cast<int>(0.02 * 30.0 * width * height / 1000.0));
}

bool LinkRate::receipts_fresh(Clock::time_point now) const {
  const double stale_ms = std::max(500.0, 4.0 * interval_ms_);
  return have_receipt_ && ms_between(last_receipt_, now) < stale_ms;
}

bool LinkRate::network_busy(const SocketSample& s) const {
  return !s.valid || s.rtt_ms - s.min_rtt_ms > params_.idle_rtt_ms;
}

bool LinkRate::receiver_held(Clock::time_point now) const {
  const double recent_ms = std::max(500.0, 4.0 * interval_ms_);
  return have_receiver_held_ && ms_between(receiver_held_at_, now) < recent_ms;
}

double LinkRate::network_queue_ms(const SocketSample& s) const {
  if (!s.valid) return standing_ms_;
  if (!network_busy(s)) return 0.0;
  return std::min(standing_ms_, params_.rtt_slack * (s.rtt_ms - s.min_rtt_ms));
}

double LinkRate::path_queue_ms(const SocketSample& s, Clock::time_point now) const {
  if (receipts_fresh(now)) return network_queue_ms(s);
  return s.valid ? std::max(0.0, s.rtt_ms - s.min_rtt_ms) : 0.0;
}

bool LinkRate::congested(double delay_ms, const SocketSample& s, Clock::time_point now, Cause& cause) const {
  // A stream near the link's rate at a low frame rate keeps each frame on the wire for most of
  // a frame interval, and its last packets wait behind its first: that much delay and round
  // trip is the frame's own, not a queue.
  const double own = 1.5 * interval_ms_;
  // A send delay is the link's only where the socket shows it full (bytes it has not sent, or a
  // delivery rate the sender was not the limit of); a busy host delays the transport's thread
  // too, on a link with room to spare.
  const bool socket_full = !s.valid || s.notsent_bytes > 0 || !s.app_limited;
  // And only where the network held the socket back: a client that reads late (a busy page)
  // closes its receive window, and the frame waits for the client, not the link (a lower rate
  // would not read it sooner).
  cause = Cause::send_delay;
  if (socket_full && !receiver_held(now) && delay_ms > std::max(params_.delay_ms, own)) return true;
  // The client's receipts show the queue frame by frame; TCP's round trip is smoothed over about
  // eight ACKs and lags it by several frames. Congested: above `queue_ms` and the frame's own
  // time; or above `queue_ms` and grown by a quarter of it since the receipt before: a queue
  // building, seen before it stands as high as a frame's own time (a delay gradient, as GCC reads
  // one; a token bucket's queue appears at once when its burst is spent). Only while TCP sees the
  // network busy: late receipts over an idle network are the client's own delay between reads,
  // which a lower rate would not shorten. (A client that knows it read a frame late sends no
  // receipt for it: issue 64, web_client/app.js and catgs-loadgen.)
  if (receipts_fresh(now)) {
    cause = Cause::receipts;
    const double queue = network_queue_ms(s);
    const bool building = queue > params_.queue_ms && standing_ms_ > standing_before_ + params_.queue_ms / 4;
    return building || queue > params_.queue_ms + receipt_own_ms_;
  }
  cause = Cause::round_trip;
  return s.valid && s.rtt_ms - s.min_rtt_ms > std::max(params_.rtt_rise_ms, own);
}

void LinkRate::on_receipt(const Receipt& r, Clock::time_point now, int ceiling_kbps) {
  // The one-way delay up to the two clocks' offset, which the minimum takes out.
  const double delay = r.received_ms - std::chrono::duration<double, std::milli>(r.sent.time_since_epoch()).count();
  if (!std::isfinite(delay)) return;
  // The frame's own time on the wire at the link's rate is no queue (congested()). It is not
  // taken out of the delay: a token bucket's burst sends a frame after a pause at the line's
  // rate, and the base would fall below the path's real one.
  receipt_own_ms_ =
      link_kbps_ > 0 ? std::min(static_cast<double>(r.bytes) * 8.0 / link_kbps_, 1.5 * interval_ms_) : 0.0;
  receipt_rate_at_ = r.rate_at;
  // The base: the least delay over the last one to two windows, so that the clocks' drift or a
  // new route moves it within a window.
  if (!have_receipt_ || now - base_since_ > params_.base_window) {
    base_before_ = have_receipt_ ? base_now_ : delay;
    base_now_ = delay;
    base_since_ = now;
  }
  base_now_ = std::min(base_now_, delay);
  const double previous = queue_ms_;
  queue_ms_ = std::max(0.0, delay - std::min(base_now_, base_before_));
  // The queue standing on the path: the lesser of the last two receipts' (a queue on the network
  // delays every frame; a host that ran the client or its browser late delays one here and there).
  standing_before_ = standing_ms_;
  standing_ms_ = have_receipt_ ? std::min(queue_ms_, previous) : queue_ms_;
  // A frame that waited behind the one before it (a queue, the two received in turn) arrived
  // its own time on the wire after it: its bytes over that interval are the link's rate, the
  // bottleneck's own (the kernel's estimate is taken at the sender, and a shaper's burst
  // inflates it). Gaps under a millisecond (a coarse client clock, messages read together) say
  // nothing; a sample beyond four times the ceiling is not this stream's link.
  const double gap_ms = r.received_ms - last_received_ms_;
  const double ceiling = ceiling_kbps > 0 ? ceiling_kbps : kNoCeilingKbps;
  if (have_receipt_ && r.sequence == last_sequence_ + 1 && queue_ms_ > params_.queue_ms / 2 && gap_ms >= 1.0 &&
      network_busy(last_sample_)) {
    const double sample = static_cast<double>(r.bytes) * 8.0 / gap_ms;
    if (sample <= 4.0 * ceiling) {
      receipt_kbps_ = average(receipt_kbps_, std::max<double>(params_.floor_kbps, sample));
      receipt_kbps_at_ = now;
      link_kbps_ = receipt_kbps_;
      if (limited_) known_kbps_ = known_kbps_ > 0 ? average(known_kbps_, receipt_kbps_) : receipt_kbps_;
    }
  }
  last_sequence_ = r.sequence;
  last_received_ms_ = r.received_ms;
  have_receipt_ = true;
  last_receipt_ = now;
  ++receipts_;
  control(now, last_sample_, ceiling_kbps);
}

void LinkRate::on_written(std::size_t bytes, Clock::time_point handed, Clock::time_point written, const SocketSample& s,
                          int ceiling_kbps) {
  delay_ms_ = std::max(0.0, ms_between(handed, written));
  // The rate the frames leave at: mean bytes a frame over the mean interval between writes
  // (a mean of per-frame rates would be ruled by the frames written back to back).
  if (have_written_) {
    const double interval = ms_between(last_written_, written);
    if (interval < 1000.0) {  // a pause is not the rate
      interval_ms_ = average(interval_ms_, interval);
      bytes_avg_ = average(bytes_avg_, static_cast<double>(bytes));
      if (interval_ms_ > 0) stream_kbps_ = bytes_avg_ * 8.0 / interval_ms_;  // bits per ms = kbit/s
    }
  }
  // Steer the encoder onto the cap: a stream above it asks for less next time, one below for more,
  // up to the cap itself.
  if (limited_ && stream_kbps_ > 0)
    gain_ = std::clamp(gain_ * std::clamp(cap_ / stream_kbps_, 0.97, 1.03), 0.5, 1.0);
  else if (!limited_)
    gain_ = 1.0;
  // The receiver's window held the socket back for a good part of this frame's send: the client
  // reads late. Its delays and delivery rate are the client's, not the link's.
  // (TCP_INFO counts from the connection's start: the first frame's is all of it.)
  if (s.valid) {
    const double rwnd_ms = s.rwnd_limited_ms - (last_sample_.valid ? last_sample_.rwnd_limited_ms : 0.0);
    if (rwnd_ms > 1.0 && rwnd_ms >= params_.rwnd_share_of_delay * delay_ms_) {
      have_receiver_held_ = true;
      receiver_held_at_ = written;
    }
  }
  have_written_ = true;
  last_written_ = written;
  if (s.valid) {
    rtt_ms_ = s.rtt_ms;
    min_rtt_ms_ = s.min_rtt_ms;
  }
  // The kernel's delivery rate where the receipts have given none for a while.
  const bool receipts_rate = receipt_kbps_ > 0 && written - receipt_kbps_at_ < std::chrono::seconds(3);
  if (s.valid && !s.app_limited && s.delivery_kbps > 0 && !receipts_rate && !receiver_held(written)) {
    link_kbps_ = s.delivery_kbps;
    // The link was full: its rate now is the one to resume at (an older one may be stale).
    if (limited_) known_kbps_ = known_kbps_ > 0 ? average(known_kbps_, s.delivery_kbps) : s.delivery_kbps;
  }
  last_sample_ = s;
  control(written, s, ceiling_kbps);
}

void LinkRate::control(Clock::time_point now, const SocketSample& s, int ceiling_kbps) {
  const double ceiling = ceiling_kbps > 0 ? ceiling_kbps : kNoCeilingKbps;
  const double queue_ms = path_queue_ms(s, now);
  Cause cause = Cause::send_delay;
  if (congested(delay_ms_, s, now, cause)) {
    last_congested_ = now;
    // One cut per hold or round trip, whichever is longer: the last one must reach the queue first.
    const auto hold = std::max<Clock::duration>(
        params_.hold, std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(rtt_ms_)));
    // A cap above the link's measured rate can only grow the queue (a cut made before the link's
    // rate was known, from the stream's own): it is cut again at once. Otherwise the last cut must
    // show first: with receipts, a frame encoded at its rate must have arrived (those before it
    // say nothing of it).
    const bool above_link = limited_ && link_kbps_ > 0 && cap_ > link_kbps_;
    if (!above_link && have_cut_ && now - last_cut_ < hold) return;
    if (!above_link && have_cut_ && receipts_fresh(now) && receipt_rate_at_ <= last_cut_) return;
    const double estimate = link_kbps_ > 0 ? link_kbps_ : stream_kbps_;
    const double from = limited_ ? cap_ : ceiling;
    // Still congested a round trip after a cut: the queue is not draining, so the cap falls
    // below the link's estimate too (multiplicative decrease from where it is). And the queue
    // standing on the path (the receipts' queue, else the round trip above its minimum; at the
    // link's rate) is drained within drain_ms: that much less for a while, so a shaper's deep
    // buffer empties in about a second instead of holding the frames behind it.
    double cap = params_.decrease * (estimate > 0 ? std::min(estimate, from) : from);
    if (estimate > 0) cap -= estimate * queue_ms / static_cast<double>(params_.drain.count());
    cap_ = std::max<double>(params_.floor_kbps, cap);
    if (link_kbps_ > 0) known_kbps_ = link_kbps_;  // what the link carried when it filled
    above_known_ = false;
    limited_ = cap_ < ceiling;
    have_cut_ = true;
    last_cut_ = now;
    last_grow_ = now;
    ++decreases_;
    ++cuts_by_cause_[static_cast<int>(cause)];
    return;
  }
  if (!limited_) return;
  const auto probe_from = last_congested_ + params_.probe_after;
  if (now < probe_from) return;
  // The queue has drained (the round trip is back near its minimum): straight back to a safe
  // share of what the link carried when it filled, instead of climbing there from the drain.
  const bool drained = receipts_fresh(now) ? queue_ms < params_.queue_ms / 2  // 0 on an idle network
                                           : !s.valid || s.rtt_ms - s.min_rtt_ms < params_.rtt_rise_ms / 4;
  if (drained && known_kbps_ > 0 && cap_ < params_.resume * known_kbps_) cap_ = params_.resume * known_kbps_;
  // Growth: fast below the known rate; slow for `probe_slow` just above it (that is where the
  // link filled last time); fast again once past it with no congestion: the link got faster.
  double rate = params_.increase_per_s;
  if (known_kbps_ > 0 && cap_ >= 0.9 * known_kbps_) {
    if (!above_known_) {
      above_known_ = true;
      above_since_ = now;
    }
    if (now - above_since_ < params_.probe_slow) rate = params_.increase_slow_per_s;
  }
  const double dt_s = ms_between(std::max(last_grow_, probe_from), now) / 1000.0;
  last_grow_ = now;
  cap_ *= 1.0 + rate * std::min(dt_s, 0.5);
  if (cap_ >= ceiling) limited_ = false;
}

int LinkRate::cap_kbps(int ceiling_kbps) const {
  if (!limited_) return ceiling_kbps;
  const double ceiling = ceiling_kbps > 0 ? ceiling_kbps : kNoCeilingKbps;
  return static_cast<int>(std::min(cap_, ceiling));
}

}  // namespace catgs::server
