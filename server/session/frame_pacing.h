// Deadline-aware frame pacing for one session (issue 35): when the host is full, a frame that
// would reach the client after its display slot is skipped before its encode (the host's scarce
// stage: x264 on the CPU), not after, so the encoder's time goes to a frame that can still be
// shown in time and a session's p99 stays near its p95 as sessions grow.
//
// The display slot of a pose is `slots` pose intervals after the pose arrived (2 at 60 poses/s:
// 33 ms, the tour latency bound); the interval is measured from the client's own pose arrivals
// (an exponential moving average, so network batching does not move it). A rendered frame is
// skipped when all of these hold:
//  - its age plus the session's typical encode time would pass the slot;
//  - a newer pose is waiting to be rendered;
//  - that pose can still make its own slot: the session's typical wait-and-render time (pose
//    arrival to rendered picture) plus its encode time fit in the slot (a host that cannot
//    render and encode in time at all, the CPU renderer say, never skips: it would skip every
//    frame);
//  - the frame before it was encoded (never two skips in a row: the stream never stalls).
// A slow host therefore lowers a session's frame rate, never stops its stream.
#pragma once

#include <chrono>

namespace catgs::server {

class FramePacing {
 public:
  using Clock = std::chrono::steady_clock;

  // slots <= 0: never skip (--frame-deadline off).
  explicit FramePacing(double slots = 2.0) : slots_(slots) {}

  // A pose arrived at `t`.
  void on_pose(Clock::time_point t);
  // A render finished `ms` milliseconds after its pose arrived (queue wait + render).
  void on_rendered(double ms);
  // An encode took `ms` milliseconds.
  void on_encode(double ms);

  double pose_interval_ms() const { return pose_interval_ms_; }
  double encode_ms() const { return encode_ms_; }
  double rendered_ms() const { return rendered_ms_; }
  // The display slot, ms after a pose arrives (0 when pacing is off).
  double deadline_ms() const { return slots_ > 0 ? slots_ * pose_interval_ms_ : 0; }

  // Whether a rendered frame of the pose that arrived at `received` should be dropped at `now`
  // instead of encoded (the rule above). Counts the decision for the no-two-in-a-row rule: call
  // once per rendered frame, when its encode could start.
  bool skip_before_encode(Clock::time_point received, Clock::time_point now, bool newer_pose_waiting);

 private:
  double slots_;
  double pose_interval_ms_ = 1000.0 / 60.0;  // until measured: the browser's rate
  double encode_ms_ = 0, rendered_ms_ = 0;   // moving averages; 0 until measured
  Clock::time_point last_pose_{};
  bool have_pose_ = false;
  bool skipped_last_ = false;
};

}  // namespace catgs::server
