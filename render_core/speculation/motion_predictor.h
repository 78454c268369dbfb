// Motion predictor (paper sec. 3.1 "Motion Prediction"; docs/DESIGN.md "Speculation" 1):
// estimates the camera's linear and angular velocity from the timestamped poses seen so far and
// predicts the pose a short time ahead. Never looks at future input.
#pragma once

#include <cstddef>
#include <deque>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

namespace catgs {

struct TimedPose {
  double time_s = 0.0;                // client clock, seconds
  glm::vec3 position{0.0f};           // camera centre, world units
  glm::quat orientation{1, 0, 0, 0};  // camera-to-world rotation (OpenCV axes)
};

struct MotionPredictorParams {
  // The angular velocity (and, without an acceleration fit, the linear velocity) is fitted over
  // the poses of the last `fit_window_s`: a longer window averages out more of the input's stamp
  // jitter, a shorter one lags less behind a changing velocity (docs/history/
  // render_core_speculation.md, "The motion predictor's fit window").
  double fit_window_s = 0.05;
  // The position is fitted as a quadratic in time (constant acceleration) over the poses of the
  // last `acceleration_window_s`; 0 keeps constant velocity (a line over fit_window_s). A line
  // fitted over a window estimates the velocity of the window's middle, which lags behind an
  // accelerating camera; the quadratic gives the velocity at the newest pose and the curvature
  // ahead. An acceleration needs a longer baseline than a velocity to stay steady under stamp
  // jitter, hence its own window (docs/history/render_core_speculation.md, "Constant
  // acceleration").
  double acceleration_window_s = 0.1;
  std::size_t max_samples = 32;  // at most this many poses are kept
  // The pose clock the two windows were tuned at (the history sections above: 120 poses/s). On a
  // slower clock (the measured pose interval, pose_interval_s()) each window widens to span as
  // many pose intervals as it spans at this rate, so the fit sees as many poses: the same motion
  // per pose then fits, and predicts a pose interval ahead, the same at 30, 60 or 120 poses/s
  // (issue 48: at 60 poses/s a 0.1 s quadratic over 6 poses instead of 12 predicted worse).
  // 0: the windows stay as given.
  double reference_rate_hz = 120.0;
};

class MotionPredictor {
 public:
  explicit MotionPredictor(const MotionPredictorParams& params = {}) : params_(params) {}

  // Adds a pose. A pose older than the newest one (out of order) is ignored; one with the same
  // timestamp replaces the newest (network batching can stamp several poses alike). Non-finite
  // input is ignored. Returns whether the pose was used.
  bool add(const TimedPose& pose);

  // Linear velocity (world units / s) at the newest pose and acceleration (world units / s^2):
  // the least-squares quadratic through the positions of the acceleration window (at least 4
  // poses; with fewer, or with acceleration_window_s = 0, the least-squares line through those of
  // the fit window and zero acceleration). The world-frame angular velocity (rad / s, axis * rate)
  // is fitted through the newest orientation over the fit window. Zero with fewer than two poses.
  glm::vec3 linear_velocity() const { return velocity_; }
  glm::vec3 linear_acceleration() const { return acceleration_; }
  glm::vec3 angular_velocity() const { return angular_velocity_; }

  // The parameters it was built with.
  const MotionPredictorParams& params() const { return params_; }

  // The newest pose; time 0 and identity before any add().
  const TimedPose& latest() const { return latest_; }
  bool empty() const { return samples_.empty(); }

  // The pose clock's interval, seconds: the median gap between consecutive kept poses (robust to
  // stamp jitter and to a pause); 0 with fewer than two poses.
  double pose_interval_s() const { return interval_s_; }
  // A fit window of `window_s` seconds as used on the measured clock: max(window_s, (window_s x
  // reference_rate_hz + 1/2) pose intervals), the half interval keeping the last pose inside
  // despite stamp rounding.
  double effective_window_s(double window_s) const;

  // Predicted pose `dt_s` seconds after the newest one: position p + v dt + a dt^2 / 2 from the
  // newest pose (constant acceleration), orientation at a constant rotation rate.
  TimedPose predict(double dt_s) const;

 private:
  void refit();
  void measure_interval();

  MotionPredictorParams params_;
  std::deque<TimedPose> samples_;
  TimedPose latest_;
  double interval_s_ = 0.0;
  glm::vec3 velocity_{0.0f}, acceleration_{0.0f}, angular_velocity_{0.0f};
};

}  // namespace catgs
