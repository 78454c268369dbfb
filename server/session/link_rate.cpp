// The per-session rate controller (link_rate.h).
#include "session/link_rate.h"

#include <algorithm>

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

bool LinkRate::congested(double delay_ms, const SocketSample& s) const {
  // A stream near the link's rate at a low frame rate keeps each frame on the wire for most of
  // a frame interval, and its last packets wait behind its first: that much delay and round
  // trip is the frame's own, not a queue.
  const double own = 1.5 * interval_ms_;
  // A send delay is the link's only where the socket shows it full (bytes it has not sent, or a
  // delivery rate the sender was not the limit of); a busy host delays the transport's thread
  // too, on a link with room to spare.
  const bool socket_full = !s.valid || s.notsent_bytes > 0 || !s.app_limited;
  if (socket_full && delay_ms > std::max(params_.delay_ms, own)) return true;
  return s.valid && s.rtt_ms - s.min_rtt_ms > std::max(params_.rtt_rise_ms, own);
}

void LinkRate::on_written(std::size_t bytes, Clock::time_point handed, Clock::time_point written, const SocketSample& s,
                          int ceiling_kbps) {
  const double ceiling = ceiling_kbps > 0 ? ceiling_kbps : kNoCeilingKbps;
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
  // Steer the encoder onto the cap: a stream above it asks for less next time, one below for more.
  if (limited_ && stream_kbps_ > 0)
    gain_ = std::clamp(gain_ * std::clamp(cap_ / stream_kbps_, 0.9, 1.1), 0.1, 2.0);
  else if (!limited_)
    gain_ = 1.0;
  have_written_ = true;
  last_written_ = written;
  if (s.valid) {
    rtt_ms_ = s.rtt_ms;
    min_rtt_ms_ = s.min_rtt_ms;
  }
  if (s.valid && !s.app_limited && s.delivery_kbps > 0) {
    link_kbps_ = s.delivery_kbps;
    // The link was full: its rate now is the one to resume at (an older one may be stale).
    if (limited_) known_kbps_ = known_kbps_ > 0 ? average(known_kbps_, s.delivery_kbps) : s.delivery_kbps;
  }

  if (congested(delay_ms_, s)) {
    last_congested_ = written;
    // One cut per hold or round trip, whichever is longer: the last one must reach the queue first.
    const auto hold = std::max<Clock::duration>(
        params_.hold, std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(rtt_ms_)));
    if (have_cut_ && written - last_cut_ < hold) return;
    const double estimate = link_kbps_ > 0 ? link_kbps_ : stream_kbps_;
    const double from = limited_ ? cap_ : ceiling;
    // Still congested a round trip after a cut: the queue is not draining, so the cap falls
    // below the link's estimate too (multiplicative decrease from where it is). And the queue
    // standing on the path (the round trip above its minimum, at the link's rate) is drained
    // within drain_ms: that much less for a while, so a shaper's deep buffer empties in about a
    // second instead of holding the frames behind it.
    double cap = params_.decrease * (estimate > 0 ? std::min(estimate, from) : from);
    if (s.valid && estimate > 0) {
      const double queue_ms = std::max(0.0, s.rtt_ms - s.min_rtt_ms);
      cap -= estimate * queue_ms / static_cast<double>(params_.drain.count());
    }
    cap_ = std::max<double>(params_.floor_kbps, cap);
    if (link_kbps_ > 0) known_kbps_ = link_kbps_;  // what the link carried when it filled
    above_known_ = false;
    limited_ = cap_ < ceiling;
    have_cut_ = true;
    last_cut_ = written;
    last_grow_ = written;
    ++decreases_;
    return;
  }
  if (!limited_) return;
  const auto probe_from = last_congested_ + params_.probe_after;
  if (written < probe_from) return;
  // The queue has drained (the round trip is back near its minimum): straight back to a safe
  // share of what the link carried when it filled, instead of climbing there from the drain.
  const bool drained = !s.valid || s.rtt_ms - s.min_rtt_ms < params_.rtt_rise_ms / 4;
  if (drained && known_kbps_ > 0 && cap_ < params_.resume * known_kbps_) cap_ = params_.resume * known_kbps_;
  // Growth: fast below the known rate; slow for `probe_slow` just above it (that is where the
  // link filled last time); fast again once past it with no congestion: the link got faster.
  double rate = params_.increase_per_s;
  if (known_kbps_ > 0 && cap_ >= 0.9 * known_kbps_) {
    if (!above_known_) {
      above_known_ = true;
      above_since_ = written;
    }
    if (written - above_since_ < params_.probe_slow) rate = params_.increase_slow_per_s;
  }
  const double dt_s = ms_between(std::max(last_grow_, probe_from), written) / 1000.0;
  last_grow_ = written;
  cap_ *= 1.0 + rate * std::min(dt_s, 0.5);
  if (cap_ >= ceiling) limited_ = false;
}

int LinkRate::cap_kbps(int ceiling_kbps) const {
  if (!limited_) return ceiling_kbps;
  const double ceiling = ceiling_kbps > 0 ? ceiling_kbps : kNoCeilingKbps;
  return static_cast<int>(std::min(cap_, ceiling));
}

}  // namespace catgs::server
