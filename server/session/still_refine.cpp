// The still view's refine frame (still_refine.h).
#include "session/still_refine.h"

namespace catgs::server {

void StillRefine::on_pose(Clock::time_point now) {
  last_pose_ = now;
  have_pose_ = true;
  taken_ = handed_ = 0;
}

void StillRefine::on_frame(bool held_back, bool refine, bool vbv_bound) {
  held_back_ = held_back && !refine;
  if (!refine) return;
  handed_++;
  vbv_bound_ = vbv_bound;
}

bool StillRefine::take(Clock::time_point now) {
  if (!have_pose_ || now - last_pose_ < kAfter || taken_ >= kFrames) return false;
  // The first after a held-back frame; the next once the one before was handed off, held by the
  // VBV's fill.
  const bool due = taken_ == 0 ? held_back_ : handed_ == taken_ && vbv_bound_;
  if (due) taken_++;
  return due;
}

}  // namespace catgs::server
