#include "speculation/motion_predictor.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace catgs {

namespace {

bool finite(const TimedPose& p) {
  return std::isfinite(p.time_s) && std::isfinite(p.position.x) && std::isfinite(p.position.y) &&
         std::isfinite(p.position.z) && std::isfinite(p.orientation.w) && std::isfinite(p.orientation.x) &&
         std::isfinite(p.orientation.y) && std::isfinite(p.orientation.z) && glm::length(p.orientation) > 1e-6f;
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

// Least-squares line through (t, position) over `poses`: its slope (averages out jitter).
glm::vec3 fit_line(const std::vector<const TimedPose*>& poses) {
  double t_mean = 0.0;
  glm::dvec3 p_mean(0.0);
  for (const TimedPose* s : poses) {
    t_mean += s->time_s;
    p_mean += glm::dvec3(s->position);
  }
  t_mean /= static_cast<double>(poses.size());
  p_mean /= static_cast<double>(poses.size());
  double stt = 0.0;
  glm::dvec3 stp(0.0);
  for (const TimedPose* s : poses) {
    const double dt = s->time_s - t_mean;
    stt += dt * dt;
    stp += dt * (glm::dvec3(s->position) - p_mean);
  }
  return stt > 0.0 ? glm::vec3(stp / stt) : glm::vec3(0.0f);
}

// Least-squares quadratic p(d) = c + v d + a d^2 / 2, d = t - t_newest, over `poses` (normal
// equations in double; d is at most a fraction of a second). False when they are degenerate
// (fewer than three distinct stamps).
bool fit_quadratic(const std::vector<const TimedPose*>& poses, double t_newest, glm::vec3* v, glm::vec3* a) {
  double m[3][3] = {};
  glm::dvec3 b[3] = {glm::dvec3(0.0), glm::dvec3(0.0), glm::dvec3(0.0)};
  for (const TimedPose* s : poses) {
    const double d = s->time_s - t_newest;
    const double f[3] = {1.0, d, 0.5 * d * d};
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) m[r][c] += f[r] * f[c];
      b[r] += f[r] * glm::dvec3(s->position);
    }
  }
  const glm::dmat3 normal(m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1], m[0][2], m[1][2], m[2][2]);
  // Scale-aware singularity test: the determinant against the product of the diagonal.
  const double det = glm::determinant(normal);
  if (!(std::fabs(det) > 1e-9 * m[0][0] * m[1][1] * m[2][2])) return false;
  const glm::dmat3 inv = glm::inverse(normal);
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 x = inv * glm::dvec3(b[0][k], b[1][k], b[2][k]);
    (*v)[k] = static_cast<float>(x[1]);
    (*a)[k] = static_cast<float>(x[2]);
  }
  return true;
}

}  // namespace

bool MotionPredictor::add(const TimedPose& in) {
  if (!finite(in)) return false;
  TimedPose pose = in;
  pose.orientation = glm::normalize(pose.orientation);
  if (!samples_.empty()) {
    if (pose.time_s < samples_.back().time_s) return false;          // out of order
    if (pose.time_s == samples_.back().time_s) samples_.pop_back();  // same stamp: newest wins
  }
  samples_.push_back(pose);
  while (samples_.size() > params_.max_samples) samples_.pop_front();
  measure_interval();
  const double keep_s =
      std::max(effective_window_s(params_.fit_window_s), effective_window_s(params_.acceleration_window_s));
  while (samples_.size() > 2 && samples_.back().time_s - samples_.front().time_s > keep_s) samples_.pop_front();
  latest_ = pose;
  refit();
  return true;
}

void MotionPredictor::measure_interval() {
  interval_s_ = 0.0;
  if (samples_.size() < 2) return;
  std::vector<double> gaps;
  gaps.reserve(samples_.size() - 1);
  for (std::size_t i = 1; i < samples_.size(); ++i) gaps.push_back(samples_[i].time_s - samples_[i - 1].time_s);
  const auto middle = gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2);
  std::nth_element(gaps.begin(), middle, gaps.end());
  interval_s_ = *middle;
}

double MotionPredictor::effective_window_s(double window_s) const {
  if (params_.reference_rate_hz <= 0.0 || interval_s_ <= 0.0) return window_s;
  return std::max(window_s, (window_s * params_.reference_rate_hz + 0.5) * interval_s_);
}

void MotionPredictor::refit() {
  velocity_ = glm::vec3(0.0f);
  acceleration_ = glm::vec3(0.0f);
  angular_velocity_ = glm::vec3(0.0f);
  if (samples_.size() < 2) return;
  const TimedPose& last = samples_.back();
  auto within = [&](double window_s) {
    std::vector<const TimedPose*> poses;
    for (const auto& s : samples_)
      if (last.time_s - s.time_s <= window_s) poses.push_back(&s);
    if (poses.size() < 2) poses = {&samples_[samples_.size() - 2], &last};  // a gap longer than the window
    return poses;
  };
  const std::vector<const TimedPose*> recent = within(effective_window_s(params_.fit_window_s));
  // Position: a quadratic over the acceleration window when it holds enough poses to be
  // overdetermined (3 would interpolate the jitter), else a line over the fit window.
  bool quadratic = false;
  if (params_.acceleration_window_s > 0.0) {
    const std::vector<const TimedPose*> longer = within(effective_window_s(params_.acceleration_window_s));
    quadratic = longer.size() >= 4 && fit_quadratic(longer, last.time_s, &velocity_, &acceleration_);
  }
  if (!quadratic) {
    velocity_ = fit_line(recent);
    acceleration_ = glm::vec3(0.0f);
  }
  // Angular velocity: slope through the origin of the rotation vectors of q_i * q_last^-1 against
  // t_i - t_last (the newest orientation is exact, older ones constrain the rate).
  const glm::quat inv_last = glm::inverse(last.orientation);
  double s2 = 0.0;
  glm::dvec3 sr(0.0);
  for (const TimedPose* s : recent) {
    const double dt = s->time_s - last.time_s;
    s2 += dt * dt;
    sr += dt * glm::dvec3(log_map(s->orientation * inv_last));
  }
  if (s2 > 0.0) angular_velocity_ = glm::vec3(sr / s2);
}

TimedPose MotionPredictor::predict(double dt_s) const {
  TimedPose p = latest_;
  p.time_s += dt_s;
  const float dt = static_cast<float>(dt_s);
  p.position += velocity_ * dt + 0.5f * acceleration_ * (dt * dt);
  p.orientation = glm::normalize(exp_map(angular_velocity_ * static_cast<float>(dt_s)) * latest_.orientation);
  return p;
}

}  // namespace catgs
