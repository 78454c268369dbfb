// The picture a visitor stops on (issue 64): it is the one looked at longest, so it must be the
// best the stream can give, whatever held the moving frames back. While the camera moves, a
// frame may be drawn smaller (adaptive_quality.h) or encoded under a rate cap (the encoder
// policy's VBV rate, the link's cap: link_rate.h), and the last of them stays on screen once the
// client stops sending poses (a still camera sends none). So when the camera has been still for
// kAfter and the last frame handed off was held back, the last pose is drawn again: a "refine"
// frame at full size, encoded at the stream's crf with no rate cap (FramePipeline), once per
// stop. x264 takes a new VBV rate at once but keeps the buffer's fill, which the capped frames
// before may have left near empty: a refine frame that lifted a VBV cap was planned against that
// fill, not the crf, and a second one follows (the buffer refilled at the new rate after the
// first), which reaches the crf's picture (NVENC and AV1 streams keep their rate, and a frame
// held back by its size alone under crf needs one). They may be
// larger than a moving frame's share of the link's rate; they are sent once, and the link
// controller does not read their time on the wire as congestion (Session).
// Pure: a function of the times and frames given (tests/unit/server/still_refine_test.cpp).
#pragma once

#include <chrono>

namespace catgs::server {

class StillRefine {
 public:
  using Clock = std::chrono::steady_clock;
  // No pose for this long: the camera stopped. Above the gap between a busy page's reads (a
  // page that stalls a few hundred ms sends no poses meanwhile, yet is still moving).
  static constexpr std::chrono::milliseconds kAfter{500};
  static constexpr int kFrames = 2;  // refine frames a stop gets at most (above)

  // A pose arrived at `now`: the camera moves, and its next stop may need a refine.
  void on_pose(Clock::time_point now);
  // A frame was handed to the transport. `held_back`: drawn below full size, at a predicted pose
  // (pose_prediction.h: the stop is elsewhere) or encoded under a
  // rate cap; `refine`: it was a refine frame, `vbv_bound` one the VBV's fill held.
  void on_frame(bool held_back, bool refine, bool vbv_bound = false);
  // True when a refine frame is due: no pose for kAfter and the last frame handed off was held
  // back (the first), or was this stop's refine frame and the VBV's fill held it (the second).
  bool take(Clock::time_point now);

 private:
  Clock::time_point last_pose_{};
  bool have_pose_ = false;
  bool held_back_ = false;  // the last frame handed off
  int taken_ = 0;           // refine frames of this stop started
  int handed_ = 0;          // and handed off
  bool vbv_bound_ = false;  // the last refine frame handed off was held by the VBV's fill
};

}  // namespace catgs::server
