// Motion predictor (paper sec. 3.1 "Motion Prediction"; DESIGN.md "Server", "Render core" 1):
// estimates the camera's linear and angular velocity from the timestamped poses seen so far and
// predicts the pose a short time ahead. Never looks at future input.
#pragma once

#include <cstddef>
#include <deque>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

namespace catgs {

struct TimedPose {
  double time_s = 0.0;               // client clock, seconds
  glm::vec3 position{0.0f};          // camera centre, world units
  glm::quat orientation{1, 0, 0, 0}; // camera-to-world rotation (OpenCV axes)
};

struct MotionPredictorParams {
  // Velocities are fitted over the poses of the last 50 ms. Measured (tests/gpu/RESULTS.md,
  // "The motion predictor's fit window"): on the real camera paths the 100 ms fit lagged enough
  // to make 78-96% of catgs frames key frames; 50 ms cut them by 5-16% (catgs 4-13% faster)
  // and, with 60 Hz input whose stamps jitter by up to 4 ms, still predicted better than 100 ms;
  // 17 ms was faster still on clean input but worse than 100 ms under that jitter.
  double fit_window_s = 0.05;
  std::size_t max_samples = 16; // and at most this many of them
};

class MotionPredictor {
 public:
  explicit MotionPredictor(const MotionPredictorParams& params = {}) : params_(params) {}

  // Adds a pose. A pose older than the newest one (out of order) is ignored; one with the same
  // timestamp replaces the newest (network batching can stamp several poses alike). Non-finite
  // input is ignored. Returns whether the pose was used.
  bool add(const TimedPose& pose);

  // Least-squares linear velocity (world units / s) of the positions in the fit window, and the
  // world-frame angular velocity (rad / s, axis * rate) fitted through the newest orientation.
  // Zero with fewer than two samples.
  glm::vec3 linear_velocity() const { return velocity_; }
  glm::vec3 angular_velocity() const { return angular_velocity_; }

  // The parameters it was built with.
  const MotionPredictorParams& params() const { return params_; }

  // The newest pose; time 0 and identity before any add().
  const TimedPose& latest() const { return latest_; }
  bool empty() const { return samples_.empty(); }

  // Predicted pose `dt_s` seconds after the newest one (constant velocity and rotation rate).
  TimedPose predict(double dt_s) const;

 private:
  void refit();

  MotionPredictorParams params_;
  std::deque<TimedPose> samples_;
  TimedPose latest_;
  glm::vec3 velocity_{0.0f}, angular_velocity_{0.0f};
};

}  // namespace catgs
