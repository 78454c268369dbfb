// Adaptive resolution for one session (--adaptive-quality): when the server cannot keep up with
// the client's poses, the session streams at a lower resolution, and it climbs back when the
// frames would fit again (when the camera stops at a reduced level, the still view's refine frame
// is full size: still_refine.h). Frames carry their size (Frame.width/height); clients scale them to
// their viewport, and every size change is an IDR (the encoder is rebuilt).
//
// The rule, evaluated on the session's tick (every 250 ms):
// - Down one level when, over the last `window`, more than `down_skip_fraction` of the poses
//   received were replaced by a newer one before being rendered (latest pose wins: the server
//   renders fewer frames than the client asks for), or when the frames come late: the median of
//   the pose-to-shown latencies the client reported in the window (Pose.shown_latency_ms, at
//   least 5 of them) exceeds max(`late_min`, `late_intervals` pose intervals). A frame can be
//   late with no pose skipped: the network or the client's decoder, not the renderer, holds it
//   (fewer pixels are fewer bits and a cheaper decode).
// - Up one level when the session has been at this level for `up_after`, the camera moved in
//   the last `window` with no pose skipped and no late median, and the frame cost measured at this level (refine
//   frames left out), scaled by the pixels of the level above, is under `up_cost_fraction` of
//   the client's pose interval (so it should still fit).
// Down needs at least 5 poses in the window, so that one skipped pose of a quiet second does not
// count.
// - After a change, no other change for `hold` (hysteresis: a level must show what it does).
// Levels scale both sides: 1, 0.75, 0.5 (1, 0.56, 0.25 of the pixels).
// The frame cost is the server's time for one frame from the pose's arrival to the frame's
// hand-off (queue + render + convert + encode, FrameTimings.total_ms), an exponential average.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>

namespace catgs::server {

class AdaptiveQuality {
 public:
  using Clock = std::chrono::steady_clock;
  using Duration = std::chrono::milliseconds;
  struct Params {
    double down_skip_fraction = 0.2;
    double up_cost_fraction = 0.6;
    Duration window{1000};
    Duration hold{2000};
    Duration up_after{3000};
    double late_intervals = 4.0;
    Duration late_min{150};
  };
  static constexpr int kLevels = 3;
  static constexpr double kScales[kLevels] = {1.0, 0.75, 0.5};

  AdaptiveQuality() = default;
  explicit AdaptiveQuality(Params params) : params_(params) {}

  // A pose arrived at `now`; `replaced` when it replaced one that was never rendered.
  void on_pose(Clock::time_point now, bool replaced);
  // The client reported at `now` that an earlier frame was shown `latency_ms` after its pose.
  void on_latency(Clock::time_point now, double latency_ms);
  // The link's rate controller (link_rate.h, --link-control) after a frame was written: `limited`
  // it holds the bitrate down; `below_floor` its cap is under link_floor_kbps of this level's
  // size; `fits_above` its cap would carry the level above. While the link limits, poses skipped
  // or frames late are the link's doing, which the bitrate answers first: the level steps down
  // only below the floor, and steps up only where the level above fits.
  void on_link(bool limited, bool below_floor, bool fits_above);
  // A frame rendered at `level` was handed off; `cost_ms` as above (not for refine frames).
  void on_frame(int level, double cost_ms);
  // The tick: applies the rule. Returns +1 (up), -1 (down) or 0.
  int on_tick(Clock::time_point now);
  int level() const { return level_; }
  double scale() const { return kScales[level_]; }
  // An even side of at least 16 pixels: `side` (even) at `level`'s scale.
  static int scaled_side(int side, int level);

 private:
  struct PoseEvent {
    Clock::time_point at;
    bool replaced;
  };
  void drop_old(Clock::time_point now);
  // The window's latencies say the frames come late (see the rule).
  bool frames_late() const;

  Params params_;
  int level_ = 0;
  Clock::time_point changed_at_{};
  bool have_change_ = false;
  std::deque<PoseEvent> poses_;  // within the last window
  struct LatencyEvent {
    Clock::time_point at;
    double ms;
  };
  std::deque<LatencyEvent> latencies_;  // within the last window
  Clock::time_point last_pose_{};
  bool have_pose_ = false;
  double pose_interval_ms_ = 0;  // exponential average
  double cost_ms_ = 0;           // exponential average, at cost_level_
  int cost_level_ = -1;
  bool link_limited_ = false, link_below_floor_ = false, link_fits_above_ = true;
};

}  // namespace catgs::server
