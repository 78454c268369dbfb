#include "session/pose_prediction.h"

#include <algorithm>

namespace catgs::server {

void PosePrediction::on_pose(const CameraPose& pose, double client_time_ms, double shown_latency_ms,
                             double display_hz) {
  const bool same = pose.position == latest_.position && pose.orientation == latest_.orientation &&
                    pose.vertical_fov_deg == latest_.vertical_fov_deg;
  moving_ = !predictor_.empty() && !same && client_time_ms - latest_ms_ <= kMaxGapMs;
  latest_ = pose;
  latest_ms_ = client_time_ms;
  predictor_.add({client_time_ms / 1000.0, pose.position, pose.orientation});
  if (shown_latency_ms > 0) {
    const double sample = std::min(shown_latency_ms, kMaxLeadMs);
    lead_ms_ = lead_ms_ > 0 ? lead_ms_ + kLeadGain * (sample - lead_ms_) : sample;
  }
  refresh_wait_ms_ = 0.5 * 1000.0 / (display_hz > 0 ? display_hz : kDefaultDisplayHz);
}

double PosePrediction::lead_ms() const {
  if (lead_ms_ <= 0) return 0.0;
  const double share =
      std::clamp((kRefreshWaitNoneMs - lead_ms_) / (kRefreshWaitNoneMs - kRefreshWaitFullMs), 0.0, 1.0);
  return std::min(lead_ms_ + share * refresh_wait_ms_, kMaxLeadMs);
}

CameraPose PosePrediction::predicted() const {
  if (lead_ms_ < 1.0 || !moving_) return latest_;
  const TimedPose ahead = predictor_.predict(lead_ms() / 1000.0);
  CameraPose p = latest_;
  p.position = ahead.position;
  p.orientation = glm::normalize(ahead.orientation);
  return p;
}

}  // namespace catgs::server
