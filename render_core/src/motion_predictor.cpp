#include "catgs/motion_predictor.h"

#include <cmath>

namespace catgs {

namespace {

bool finite(const TimedPose& p) {
  return std::isfinite(p.time_s) && std::isfinite(p.position.x) && std::isfinite(p.position.y) &&
         std::isfinite(p.position.z) && std::isfinite(p.orientation.w) &&
         std::isfinite(p.orientation.x) && std::isfinite(p.orientation.y) &&
         std::isfinite(p.orientation.z) && glm::length(p.orientation) > 1e-6f;
}

// Rotation vector (axis * angle, radians) of a unit quaternion, angle in [0, pi].
glm::vec3 log_map(glm::quat q) {
  if (q.w < 0) q = -q;
  const glm::vec3 v(q.x, q.y, q.z);
  const float s = glm::length(v);
  if (s < 1e-8f) return 2.0f * v;
  return v * (2.0f * std::atan2(s, q.w) / s);
}

glm::quat exp_map(glm::vec3 r) {
  const float angle = glm::length(r);
  if (angle < 1e-8f) return glm::normalize(glm::quat(1.0f, 0.5f * r.x, 0.5f * r.y, 0.5f * r.z));
  return glm::angleAxis(angle, r / angle);
}

}  // namespace

bool MotionPredictor::add(const TimedPose& in) {
  if (!finite(in)) return false;
  TimedPose pose = in;
  pose.orientation = glm::normalize(pose.orientation);
  if (!samples_.empty()) {
    if (pose.time_s < samples_.back().time_s) return false;  // out of order
    if (pose.time_s == samples_.back().time_s) samples_.pop_back();  // same stamp: newest wins
  }
  samples_.push_back(pose);
  while (samples_.size() > params_.max_samples) samples_.pop_front();
  while (samples_.size() > 2 && samples_.back().time_s - samples_.front().time_s > params_.fit_window_s)
    samples_.pop_front();
  latest_ = pose;
  refit();
  return true;
}

void MotionPredictor::refit() {
  velocity_ = glm::vec3(0.0f);
  angular_velocity_ = glm::vec3(0.0f);
  if (samples_.size() < 2) return;
  const TimedPose& last = samples_.back();
  // Linear velocity: slope of the least-squares line through (t, position) (averages out jitter).
  double t_mean = 0.0;
  glm::dvec3 p_mean(0.0);
  for (const auto& s : samples_) {
    t_mean += s.time_s;
    p_mean += glm::dvec3(s.position);
  }
  t_mean /= static_cast<double>(samples_.size());
  p_mean /= static_cast<double>(samples_.size());
  double stt = 0.0;
  glm::dvec3 stp(0.0);
  for (const auto& s : samples_) {
    const double dt = s.time_s - t_mean;
    stt += dt * dt;
    stp += dt * (glm::dvec3(s.position) - p_mean);
  }
  if (stt > 0.0) velocity_ = glm::vec3(stp / stt);
  // Angular velocity: slope through the origin of the rotation vectors of q_i * q_last^-1 against
  // t_i - t_last (the newest orientation is exact, older ones constrain the rate).
  const glm::quat inv_last = glm::inverse(last.orientation);
  double s2 = 0.0;
  glm::dvec3 sr(0.0);
  for (const auto& s : samples_) {
    const double dt = s.time_s - last.time_s;
    s2 += dt * dt;
    sr += dt * glm::dvec3(log_map(s.orientation * inv_last));
  }
  if (s2 > 0.0) angular_velocity_ = glm::vec3(sr / s2);
}

TimedPose MotionPredictor::predict(double dt_s) const {
  TimedPose p = latest_;
  p.time_s += dt_s;
  p.position += velocity_ * static_cast<float>(dt_s);
  p.orientation = glm::normalize(exp_map(angular_velocity_ * static_cast<float>(dt_s)) * latest_.orientation);
  return p;
}

}  // namespace catgs
