#include "session/frame_pacing.h"

#include <algorithm>

namespace catgs::server {

namespace {

constexpr double kSmoothing = 0.1;  // EMA weight of a new sample: about the last 10 poses/frames
// Pose gaps outside this range are pauses (the camera stopped) or bursts, not the pose rate.
constexpr double kMinIntervalMs = 4.0, kMaxIntervalMs = 100.0;

void smooth(double& average, double sample) {
  average = average == 0 ? sample : average + kSmoothing * (sample - average);
}

}  // namespace

void FramePacing::on_pose(Clock::time_point t) {
  if (have_pose_) {
    const double gap = std::chrono::duration<double, std::milli>(t - last_pose_).count();
    if (gap >= kMinIntervalMs && gap <= kMaxIntervalMs) pose_interval_ms_ += kSmoothing * (gap - pose_interval_ms_);
  }
  last_pose_ = t;
  have_pose_ = true;
}

void FramePacing::on_rendered(double ms) { smooth(rendered_ms_, ms); }

void FramePacing::on_encode(double ms) { smooth(encode_ms_, ms); }

bool FramePacing::skip_before_encode(Clock::time_point received, Clock::time_point now, bool newer_pose_waiting) {
  const double age = std::chrono::duration<double, std::milli>(now - received).count();
  const bool skip = slots_ > 0 && newer_pose_waiting && !skipped_last_ && age + encode_ms_ > deadline_ms() &&
                    rendered_ms_ + encode_ms_ <= deadline_ms();
  skipped_last_ = skip;
  return skip;
}

}  // namespace catgs::server
