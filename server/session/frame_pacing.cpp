#include "session/frame_pacing.h"

#include <algorithm>

namespace catgs::server {

namespace {

constexpr double kSmoothing = 0.1;  // EMA weight of a new sample: about the last 10 poses/frames
// Pose gaps outside this range are pauses (the camera stopped) or bursts, not the pose rate.
constexpr double kMinIntervalMs = 4.0, kMaxIntervalMs = 100.0;

}  // namespace

void FramePacing::on_pose(Clock::time_point t) {
  if (have_pose_) {
    const double gap = std::chrono::duration<double, std::milli>(t - last_pose_).count();
    if (gap >= kMinIntervalMs && gap <= kMaxIntervalMs) pose_interval_ms_ += kSmoothing * (gap - pose_interval_ms_);
  }
  last_pose_ = t;
  have_pose_ = true;
}

void FramePacing::on_encode(double ms) {
  encode_ms_ = encode_ms_ == 0 ? ms : encode_ms_ + kSmoothing * (ms - encode_ms_);
}

bool FramePacing::skip_before_encode(Clock::time_point received, Clock::time_point now, bool newer_pose_waiting) const {
  if (slots_ <= 0 || !newer_pose_waiting) return false;
  const double age = std::chrono::duration<double, std::milli>(now - received).count();
  return age + encode_ms_ > deadline_ms();
}

}  // namespace catgs::server
