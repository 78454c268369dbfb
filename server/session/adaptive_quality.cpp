#include "session/adaptive_quality.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace catgs::server {

namespace {
constexpr double kAverageWeight = 0.2;  // of the newest sample in the exponential averages

double average(double mean, double sample, bool first) {
  return first ? sample : mean + kAverageWeight * (sample - mean);
}
}  // namespace

void AdaptiveQuality::on_pose(Clock::time_point now, bool replaced) {
  if (have_pose_) {
    const double gap = std::chrono::duration<double, std::milli>(now - last_pose_).count();
    // A pause (the camera stopped, then moved again) is not the pose rate.
    if (gap < 1000.0) pose_interval_ms_ = average(pose_interval_ms_, gap, pose_interval_ms_ == 0);
  }
  have_pose_ = true;
  last_pose_ = now;
  poses_.push_back({now, replaced});
  drop_old(now);
}

void AdaptiveQuality::on_link(bool limited, bool below_floor, bool fits_above) {
  link_limited_ = limited;
  link_below_floor_ = below_floor;
  link_fits_above_ = fits_above;
}

void AdaptiveQuality::on_frame(int level, double cost_ms) {
  cost_ms_ = average(cost_ms_, cost_ms, level != cost_level_);
  cost_level_ = level;
}

void AdaptiveQuality::on_latency(Clock::time_point now, double latency_ms) {
  latencies_.push_back({now, latency_ms});
  drop_old(now);
}

void AdaptiveQuality::drop_old(Clock::time_point now) {
  while (!poses_.empty() && now - poses_.front().at > params_.window) poses_.pop_front();
  while (!latencies_.empty() && now - latencies_.front().at > params_.window) latencies_.pop_front();
}

bool AdaptiveQuality::frames_late() const {
  if (latencies_.size() < 5 || pose_interval_ms_ <= 0) return false;
  std::vector<double> ms;
  for (const LatencyEvent& l : latencies_) ms.push_back(l.ms);
  std::nth_element(ms.begin(), ms.begin() + static_cast<std::ptrdiff_t>(ms.size() / 2), ms.end());
  const double limit = std::max(std::chrono::duration<double, std::milli>(params_.late_min).count(),
                                params_.late_intervals * pose_interval_ms_);
  return ms[ms.size() / 2] > limit;
}

int AdaptiveQuality::on_tick(Clock::time_point now) {
  drop_old(now);
  if (have_change_ && now - changed_at_ < params_.hold) return 0;
  std::size_t replaced = 0;
  for (const PoseEvent& p : poses_) replaced += p.replaced ? 1 : 0;
  const auto received = poses_.size();
  int step = 0;
  // At least a few poses, so that one replaced pose in a quiet second does not count.
  const bool skipping =
      received >= 5 && static_cast<double>(replaced) > params_.down_skip_fraction * static_cast<double>(received);
  const bool late = frames_late();
  // A link that holds the bitrate down explains the skips and the lateness until it is below
  // the floor (bitrate first, then resolution).
  const bool host_behind = (skipping || late) && !link_limited_;
  if ((host_behind || link_below_floor_) && level_ + 1 < kLevels) {
    step = -1;
  } else if (level_ > 0 && received >= 1 && (replaced == 0 || link_limited_) && !late && link_fits_above_ &&
             (!have_change_ || now - changed_at_ >= params_.up_after) && cost_level_ == level_ &&
             pose_interval_ms_ > 0) {
    const double grow = kScales[level_ - 1] / kScales[level_];
    if (cost_ms_ * grow * grow < params_.up_cost_fraction * pose_interval_ms_) step = +1;
  }
  if (step == 0) return 0;
  level_ -= step;  // down a level is a larger index
  changed_at_ = now;
  have_change_ = true;
  poses_.clear();  // the next decision looks at the new level only
  latencies_.clear();
  return step;
}

int AdaptiveQuality::scaled_side(int side, int level) {
  const double s = kScales[std::clamp(level, 0, kLevels - 1)];
  const int scaled = static_cast<int>(std::lround(side * s / 2.0)) * 2;
  return std::min(side, std::max(16, scaled));
}

}  // namespace catgs::server
