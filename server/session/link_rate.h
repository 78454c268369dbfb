// The stream's bitrate follows the visitor's link (issue 50): a per-session rate controller that
// lowers the encoder's maximum rate when the link cannot carry the stream and raises it again
// when it can, so frames wait in the session (where the latest pose wins) instead of piling up
// in a socket buffer as seconds of lag.
//
// What it sees, per frame the transport finished writing (Session::post_sent):
// - the send delay: frame handed to the transport -> its last byte accepted by the kernel. The
//   server keeps the kernel's unsent queue small (TCP_NOTSENT_LOWAT, --notsent-lowat), so a
//   socket only takes the next frame once the previous one has nearly left: on a link slower
//   than the stream the delay grows by a frame's serialisation time per frame;
// - TCP_INFO at that moment (SocketSample): the kernel's delivery-rate estimate (bytes acked per
//   interval; not trusted when the kernel marks it application-limited, as it is whenever the
//   stream is slower than the link) and the smoothed and minimum round-trip times. A queue in
//   front of a slow link (a shaper, a Wi-Fi access point) shows as round-trip time above the
//   minimum.
// - the client's receipts (Pose.received_frame_sequence / received_ms, Session::handle_pose): when
//   a frame arrived, on the client's clock. Less the time it was handed over, on the server's,
//   that is the one-way delay up to the clocks' offset; above its least value of the last
//   `base_window` or two it is the queue on the path, frame by frame. TCP's round trip is
//   smoothed over about eight ACKs and shows the same queue several frames later; it stands in
//   for clients that send no receipts. Two frames received in turn, the second behind a queue,
//   arrived the second's time on the wire apart: its bytes over that gap are the bottleneck's
//   rate (the kernel's delivery rate is the sender's view, and a shaper's burst inflates it).
// A client that reads late (a busy page, a busy host) is not a slow link (issue 64): a send the
// receiver's window held back (tcpi_rwnd_limited) is not the network's delay, and its delivery
// rate is the client's reading, not the link's; the receipts' queue is the lesser of the last two
// (a host that ran the client late delays one frame here and there, a network queue every frame),
// and counts only up to twice the round trip's rise (a network queue delays the ACKs as well).
// A receipt says when a frame arrived only if the
// client was listening: the page and catgs-loadgen send none for a frame they read after their
// thread was away (web_client/app.js, tools/loadgen), so late reads never look like a queue.
// The rule (a delay-based AIMD, as WebRTC's and Selkies' congestion control do in spirit):
// - congested: the send delay passes `delay_ms` (at least 1.5 frame intervals: a frame's own
//   time on the wire at a low frame rate is no queue); or the receipts' queue passes `queue_ms`
//   plus the frame's own time on the wire (at most 1.5 intervals), or passes `queue_ms` while
//   still growing (by a quarter of it since the receipt before: a delay gradient, as GCC reads
//   one; a token bucket's queue appears at once when its burst is spent); without receipts, the
//   smoothed RTT passes the minimum by `rtt_rise_ms` (at least 1.5 frame intervals). Then, at
//   most once per `hold` or round trip (the previous cut must show in the queue first) and, with
//   receipts, only once a frame encoded at the rate the last cut set has arrived (at once while
//   the cap stands above the link's measured rate: a first cut before the rate was known), the
//   cap drops to `decrease` x the link's rate (the receipts', else the kernel's last estimate that was not
//   application-limited, else the rate the frames leave at) or x the current cap, whichever is
//   lower, less the rate that drains the queue standing on the path (the receipts', else the RTT
//   above its minimum; at the link's rate) within `drain`; at least `floor_kbps`.
// - clear for `probe_after`: once the queue is back near nothing (drained) the
//   cap resumes at `resume` x the rate the link carried when it filled (the known rate), then
//   grows by `increase_per_s` per second (multiplicatively), slowly (`increase_slow_per_s`) for
//   `probe_slow` just above the known rate, where the link filled last time, and fast again past
//   it (the link got faster), until it reaches the ceiling, the encoder policy's rate, where the
//   controller stops limiting.
// Pure: a function of the samples and the times given; tests drive it without sockets
// (tests/unit/server/link_rate_test.cpp).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>

#include "transport/connection_link.h"

namespace catgs::server {

// The least rate worth streaming a width x height picture at before its size steps down
// (adaptive_quality.h): 0.02 bits a pixel at 30 frames/s, at least 30 kbit/s (640x360: 138
// kbit/s, 1280x720: 553, 1920x1080: 1244). Below it x264's picture falls apart faster than a
// smaller picture scaled up by the page loses detail.
int link_floor_kbps(int width, int height);

class LinkRate {
 public:
  using Clock = std::chrono::steady_clock;
  struct Params {
    double delay_ms = 40.0;     // send delay that means the socket is backed up
    double rtt_rise_ms = 60.0;  // RTT above the minimum that means a queue (over a delayed ACK)
    // TCP's round trip within this of its minimum: the network holds no queue, whatever the
    // receipts say (a client busy between reads, rendering or decoding, stamps its receipts late;
    // its kernel still acknowledges at once, so the round trip stays at its minimum).
    double idle_rtt_ms = 2.0;
    // A queue on the network delays TCP's acknowledgements as much as the frames: the receipts'
    // queue counts up to this many times the round trip's rise (the smoothed round trip lags a
    // building queue by a few ACKs). A host that runs the client or its browser late (their
    // scheduling, not the wire) delays the receipts by far more than the round trip.
    double rtt_slack = 2.0;
    // The receiver's window held the socket (tcpi_rwnd_limited) for at least this share of a
    // frame's send delay: the client reads late, its delay is not the link's (issue 64).
    double rwnd_share_of_delay = 0.25;
    double queue_ms = 40.0;                        // the receipts' one-way delay above its base that means a queue
    std::chrono::milliseconds base_window{10000};  // the receipts' base is the least of 1-2 of these
    double decrease = 0.85;                        // of the link's rate, on congestion
    double increase_per_s = 0.7;
    std::chrono::milliseconds hold{400};
    std::chrono::milliseconds probe_after{500};
    std::chrono::milliseconds drain{1000};  // a standing queue is emptied within this
    double resume = 0.8;                    // of the known rate, once the queue has drained
    double increase_slow_per_s = 0.05;      // just above the known rate
    std::chrono::milliseconds probe_slow{1500};
    int floor_kbps = 50;  // the cap never goes below this
  };

  LinkRate() = default;
  explicit LinkRate(Params params) : params_(params) {}

  // The ceiling used for a policy without one (crf alone): the largest Quality.max_bitrate_kbps.
  static constexpr int kNoCeilingKbps = 100000;

  // A frame of `bytes` handed to the transport at `handed` was fully written at `written`, with
  // the socket's state `s` then; `ceiling_kbps` is the encoder policy's rate for the stream now
  // (0: crf alone, taken as kNoCeilingKbps).
  void on_written(std::size_t bytes, Clock::time_point handed, Clock::time_point written, const SocketSample& s,
                  int ceiling_kbps);

  // A client's receipt: frame `sequence` (Frame.sequence) of `bytes`, encoded at the rate read at
  // `rate_at`, left the server at `sent` and arrived when the client's clock read `received_ms`
  // (any finite value: a hostile one moves only this session's cap). `sent` is when the kernel
  // took its last byte (the session's written time; its hand-off to the transport while that is
  // not known): a frame that waited in a busy server's transport is the server's delay, which
  // the send delay (on_written) reads where the socket shows it, not the network's queue.
  struct Receipt {
    std::uint32_t sequence = 0;
    std::size_t bytes = 0;
    Clock::time_point sent{}, rate_at{};
    double received_ms = 0;
  };
  // The receipt reached the server at `now`; `ceiling_kbps` as above.
  void on_receipt(const Receipt& r, Clock::time_point now, int ceiling_kbps);

  // The encoder's maximum rate, kbit/s: `ceiling_kbps` while not limiting, else the controller's
  // cap (below the ceiling).
  int cap_kbps(int ceiling_kbps) const;
  // The controller holds the stream below the policy's rate.
  bool limited() const { return limited_; }
  // Estimates, for /metrics and the page's stats (0 until known). The link's rate: the receipts'
  // bottleneck rate, else the kernel's delivery rate when it was not application-limited.
  double link_kbps() const { return link_kbps_; }
  double rtt_ms() const { return rtt_ms_; }
  double send_delay_ms() const { return delay_ms_; }
  double stream_kbps() const { return stream_kbps_; }  // the rate frames leave at
  double min_rtt_ms() const { return min_rtt_ms_; }    // the connection's minimum round trip
  double queue_ms() const { return queue_ms_; }        // the newest receipt's queue (0 without)
  int receipts() const { return receipts_; }
  int decreases() const { return decreases_; }
  // What the cuts so far read as congestion: the send delay of a frame the socket held, the
  // receipts' queue, the round trip alone (no fresh receipts). For /metrics.
  enum class Cause { send_delay, receipts, round_trip };
  static constexpr int kCauses = 3;
  int decreases(Cause c) const { return cuts_by_cause_[static_cast<int>(c)]; }
  // Frames written per second (an exponential average of the intervals; 0 until two frames).
  // The encoder's VBV counts its rate per frame at the stream's nominal 60 frames/s, so a stream
  // that runs at fewer frames spends only rate x fps / 60: the session converts with it.
  double frame_rate() const { return interval_ms_ > 0 ? 1000.0 / interval_ms_ : 0.0; }
  // The encoder overshoots a low VBV rate (x264's frame sizes, the Frame message around each):
  // the ratio of the cap to the rate the frames really left at, followed while limiting by at
  // most 3% a frame within [0.5, 1] (1 otherwise), by which the session scales the VBV rate it
  // asks for. Never above 1: a stream below its cap (the cap rising faster than x264 follows)
  // must not wind it up into frames larger than the cap once x264 catches up.
  double encoder_gain() const { return gain_; }

 private:
  // The cut or the growth, after a written frame or a receipt.
  void control(Clock::time_point now, const SocketSample& s, int ceiling_kbps);
  // Whether the path is congested now, and what says so.
  bool congested(double delay_ms, const SocketSample& s, Clock::time_point now, Cause& cause) const;
  // A receipt came within the last 500 ms or 4 frame intervals: the receipts speak for the path.
  bool receipts_fresh(Clock::time_point now) const;
  // TCP's round trip shows a queue could stand on the network (above idle_rtt_ms; or no TCP_INFO).
  bool network_busy(const SocketSample& s) const;
  // The queue on the path now, ms: the receipts', else the round trip above its minimum.
  double path_queue_ms(const SocketSample& s, Clock::time_point now) const;
  // The receipts' queue as far as the network shows it: standing_ms_, up to rtt_slack x the round
  // trip's rise (0 while the round trip is at its minimum; all of it without TCP_INFO).
  double network_queue_ms(const SocketSample& s) const;
  // The receiver's window held a frame's send back within the last 500 ms or 4 frame intervals.
  bool receiver_held(Clock::time_point now) const;

  Params params_;
  bool limited_ = false;
  double cap_ = 0;  // kbit/s while limited
  double link_kbps_ = 0, rtt_ms_ = 0, min_rtt_ms_ = 0, delay_ms_ = 0;
  Clock::time_point last_written_{}, last_cut_{}, last_congested_{}, last_grow_{};
  bool have_written_ = false, have_cut_ = false;
  double bytes_avg_ = 0;    // a frame's bytes (exponential average)
  double stream_kbps_ = 0;  // the rate frames leave at: bytes_avg_ over interval_ms_
  double interval_ms_ = 0;  // between frames written (exponential average)
  double known_kbps_ = 0;   // the link's rate when it last filled (0: unknown)
  double gain_ = 1.0;       // encoder_gain()
  bool above_known_ = false;
  Clock::time_point above_since_{};
  int decreases_ = 0;
  int cuts_by_cause_[kCauses] = {};
  SocketSample last_sample_{};  // the newest written frame's, for a receipt's decision
  bool have_receiver_held_ = false;
  Clock::time_point receiver_held_at_{};  // the last frame whose send the client's window held
  // Receipts: the one-way delay's base (the least of this window and the one before), the newest
  // one's queue above it.
  bool have_receipt_ = false;
  Clock::time_point last_receipt_{}, base_since_{};
  double base_now_ = 0, base_before_ = 0, queue_ms_ = 0;
  double standing_ms_ = 0;               // the lesser of the last two receipts' queues (on_receipt)
  double standing_before_ = 0;           // the same one receipt before
  double receipt_own_ms_ = 0;            // the newest receipt's frame's own time on the wire
  Clock::time_point receipt_rate_at_{};  // when that frame's encoder rate was read
  std::uint32_t last_sequence_ = 0;      // the newest receipt's frame and its arrival (client ms)
  double last_received_ms_ = 0;
  double receipt_kbps_ = 0;  // the link's rate from queued frames' arrivals (0: none yet)
  Clock::time_point receipt_kbps_at_{};
  int receipts_ = 0;
};

}  // namespace catgs::server
