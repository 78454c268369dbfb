#include "session/pose_prediction.h"

#include <algorithm>

namespace catgs::server {

void PosePrediction::on_pose(const CameraPose& pose, double client_time_ms, double shown_latency_ms) {
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
}

CameraPose PosePrediction::predicted() const {
  if (lead_ms_ < 1.0 || !moving_) return latest_;
  const TimedPose ahead = predictor_.predict(lead_ms_ / 1000.0);
  CameraPose p = latest_;
  p.position = ahead.position;
  p.orientation = glm::normalize(ahead.orientation);
  return p;
}

}  // namespace catgs::server
