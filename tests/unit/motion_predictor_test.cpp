// Motion predictor: exact on constant motion, robust to jitter, repeated and out-of-order stamps,
// stops, and useful on a real camera path.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>

#include <gtest/gtest.h>

#include "speculation/motion_predictor.h"
#include "speculation/speculation_planner.h"
#include "camera/trace.h"
#include "test_data.h"

namespace catgs {
namespace {

TimedPose pose_at(double t, glm::vec3 v, glm::vec3 omega) {
  TimedPose p;
  p.time_s = t;
  p.position = glm::vec3(1.0f, 2.0f, 3.0f) + v * static_cast<float>(t);
  const float angle = glm::length(omega) * static_cast<float>(t);
  p.orientation = angle > 0 ? glm::angleAxis(angle, glm::normalize(omega)) : glm::quat(1, 0, 0, 0);
  return p;
}

float angle_between(glm::quat a, glm::quat b) { return 2.0f * std::acos(std::fmin(1.0f, std::fabs(glm::dot(a, b)))); }

TEST(MotionPredictor, ConstantMotionIsPredictedExactly) {
  const glm::vec3 v(0.5f, -0.2f, 1.0f), omega(0.0f, 1.2f, 0.3f);
  MotionPredictor mp;
  for (int i = 0; i <= 12; ++i) ASSERT_TRUE(mp.add(pose_at(i / 120.0, v, omega)));
  EXPECT_NEAR(glm::distance(mp.linear_velocity(), v), 0.0f, 1e-3f);
  EXPECT_NEAR(glm::distance(mp.angular_velocity(), omega), 0.0f, 1e-3f);
  const TimedPose want = pose_at(16 / 120.0, v, omega), got = mp.predict(4 / 120.0);
  EXPECT_NEAR(glm::distance(got.position, want.position), 0.0f, 1e-4f);
  EXPECT_LT(angle_between(got.orientation, want.orientation), 1e-3f);
}

TEST(MotionPredictor, JitterAveragesOut) {
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  const glm::vec3 v(1.0f, 0.0f, 0.0f);
  MotionPredictor mp;
  for (int i = 0; i < 12; ++i) {
    TimedPose p = pose_at(i / 120.0 + 0.0005 * noise(rng), v, glm::vec3(0.0f));
    p.position += glm::vec3(noise(rng), noise(rng), noise(rng));
    mp.add(p);
  }
  EXPECT_NEAR(mp.linear_velocity().x, 1.0f, 0.15f);
  EXPECT_NEAR(glm::length(mp.angular_velocity()), 0.0f, 1e-3f);
}

TEST(MotionPredictor, RepeatedOutOfOrderAndNonFiniteStamps) {
  const glm::vec3 v(0.0f, 0.0f, 2.0f);
  MotionPredictor mp;
  for (int i = 0; i < 6; ++i) mp.add(pose_at(i / 120.0, v, {}));
  EXPECT_FALSE(mp.add(pose_at(2 / 120.0, {}, {})));  // out of order: ignored
  TimedPose bad = pose_at(7 / 120.0, v, {});
  bad.position.x = NAN;
  EXPECT_FALSE(mp.add(bad));
  EXPECT_NEAR(mp.linear_velocity().z, 2.0f, 1e-3f);
  // A repeated stamp replaces the newest pose instead of making an infinite velocity.
  EXPECT_TRUE(mp.add(pose_at(5 / 120.0, v, {})));
  EXPECT_TRUE(std::isfinite(mp.linear_velocity().z));
  EXPECT_NEAR(mp.linear_velocity().z, 2.0f, 1e-3f);
}

TEST(MotionPredictor, AStoppedCameraPredictsStillness) {
  const glm::vec3 v(3.0f, 0.0f, 0.0f), omega(0.0f, 2.0f, 0.0f);
  MotionPredictor mp;
  for (int i = 0; i < 10; ++i) mp.add(pose_at(i / 120.0, v, omega));
  const TimedPose still = pose_at(9 / 120.0, v, omega);
  for (int i = 10; i < 40; ++i) {
    TimedPose p = still;
    p.time_s = i / 120.0;
    mp.add(p);
  }
  EXPECT_LT(glm::length(mp.linear_velocity()), 1e-3f);
  EXPECT_LT(glm::length(mp.angular_velocity()), 1e-3f);
  EXPECT_NEAR(glm::distance(mp.predict(0.05).position, still.position), 0.0f, 1e-4f);
}

// On a real hand-held path (Tanks&Temples "train", interpolated to 120 Hz) the 4-frame-ahead
// prediction is far closer to the truth than assuming the camera stands still.
TEST(MotionPredictor, BeatsHoldingStillOnARealPath) {
  CATGS_REQUIRE_DATA(path, "traces/tandt_train.cameras.json");
  const Trace trace = interpolate_views(load_inria_cameras(path, 320, 180), 120.0, 0.5);
  MotionPredictor mp;
  double err_pred = 0.0, err_hold = 0.0;
  for (std::size_t i = 0; i + 4 < trace.size(); ++i) {
    mp.add({trace[i].time_s, trace[i].camera.position(), trace[i].camera.orientation()});
    if (i < 8) continue;
    const TimedPose p = mp.predict(trace[i + 4].time_s - trace[i].time_s);
    err_pred += glm::distance(p.position, trace[i + 4].camera.position());
    err_hold += glm::distance(trace[i].camera.position(), trace[i + 4].camera.position());
  }
  std::cout << "[ info ] tandt_train 4-frame position error: predicted " << err_pred << ", held " << err_hold << "\n";
  EXPECT_LT(err_pred, 0.2 * err_hold);
}

// A camera that speeds up (constant acceleration along x, world units / s^2).
TimedPose accelerating_at(double t, float a) {
  TimedPose p;
  p.time_s = t;
  p.position = glm::vec3(0.5f * a * static_cast<float>(t * t), 0.0f, 0.0f);
  return p;
}

float error_4_ahead_accelerating(const MotionPredictorParams& params) {
  MotionPredictor mp(params);
  for (int i = 0; i <= 24; ++i) mp.add(accelerating_at(i / 120.0, 4.0f));
  return glm::distance(mp.predict(4 / 120.0).position, accelerating_at(28 / 120.0, 4.0f).position);
}

// At constant velocity (acceleration_window_s = 0) the fit over a shorter window lags less behind
// the current velocity (SpeculationParams::predictor), and the planner refuses a window
// outside (0, 1] s.
TEST(MotionPredictor, AShortWindowLagsLessOnAnAcceleratingCamera) {
  MotionPredictorParams params;
  params.acceleration_window_s = 0.0;
  params.fit_window_s = 0.1;
  const float long_fit = error_4_ahead_accelerating(params);
  params.fit_window_s = 0.017;
  const float short_fit = error_4_ahead_accelerating(params);
  std::cout << "[ info ] 4-frame error, accelerating: 100 ms fit " << long_fit << ", 17 ms fit " << short_fit << "\n";
  EXPECT_LT(short_fit, 0.5f * long_fit);
  SpeculationParams bad;
  bad.predictor.fit_window_s = 0.0;
  EXPECT_THROW(SpeculationPlanner{bad}, std::invalid_argument);
  bad.predictor.fit_window_s = 0.017;
  EXPECT_NO_THROW(SpeculationPlanner{bad});
  bad.predictor.acceleration_window_s = -0.1;
  EXPECT_THROW(SpeculationPlanner{bad}, std::invalid_argument);
  bad.predictor.acceleration_window_s = 0.0;
  EXPECT_NO_THROW(SpeculationPlanner{bad});
}

// The quadratic fit (the default) predicts a constant acceleration exactly; constant velocity
// cannot, whatever its window.
TEST(MotionPredictor, ConstantAccelerationIsPredictedExactly) {
  MotionPredictorParams params;
  const float quadratic = error_4_ahead_accelerating(params);
  MotionPredictor mp(params);
  for (int i = 0; i <= 24; ++i) mp.add(accelerating_at(i / 120.0, 4.0f));
  EXPECT_NEAR(mp.linear_acceleration().x, 4.0f, 1e-2f);
  EXPECT_NEAR(mp.linear_velocity().x, 4.0f * 24 / 120.0f, 1e-3f);  // at the newest pose, not the window's middle
  params.acceleration_window_s = 0.0;
  params.fit_window_s = 0.017;
  const float linear = error_4_ahead_accelerating(params);
  std::cout << "[ info ] 4-frame error, accelerating: quadratic " << quadratic << ", 17 ms line " << linear << "\n";
  EXPECT_LT(quadratic, 1e-4f);
  EXPECT_GT(linear, 1e-3f);
}

// Browser-like input: 60 Hz poses whose stamps jitter by up to +-4 ms, on a constant velocity.
// The acceleration fit must not turn the jitter into large accelerations: its 4-frames-ahead
// error stays a small part of the 4-frame motion (0.033 world units).
TEST(MotionPredictor, JitteredStampsDoNotMakeAnAcceleration) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> jitter(-0.004, 0.004);
  const glm::vec3 v(1.0f, 0.0f, 0.0f);
  MotionPredictor mp;
  double worst = 0.0;
  for (int i = 0; i < 120; ++i) {
    const double t = i / 60.0;
    TimedPose p = pose_at(t, v, {});
    p.time_s = t + jitter(rng);
    mp.add(p);
    if (i < 8) continue;
    const TimedPose got = mp.predict(4 / 120.0);
    worst = std::max<double>(worst, glm::distance(got.position, pose_at(t + 4 / 120.0, v, {}).position));
  }
  std::cout << "[ info ] jittered 60 Hz input, worst 4-frame error " << worst << " (motion 0.033)\n";
  EXPECT_LT(worst, 0.5 * (4 / 120.0));
}

// On a real path with changing velocity (mipnerf360 "bicycle", interpolated to 120 Hz), the
// acceleration fit predicts 4 frames ahead better than constant velocity over the same poses.
TEST(MotionPredictor, AccelerationBeatsConstantVelocityOnARealPath) {
  CATGS_REQUIRE_DATA(path, "traces/mipnerf360_bicycle.cameras.json");
  const Trace trace = interpolate_views(load_inria_cameras(path, 320, 180), 120.0, 0.5);
  MotionPredictorParams linear_params;
  linear_params.acceleration_window_s = 0.0;
  MotionPredictor quadratic, linear(linear_params);
  double err_quadratic = 0.0, err_linear = 0.0;
  for (std::size_t i = 0; i + 4 < trace.size(); ++i) {
    const TimedPose pose{trace[i].time_s, trace[i].camera.position(), trace[i].camera.orientation()};
    quadratic.add(pose);
    linear.add(pose);
    if (i < 12) continue;
    const double dt = trace[i + 4].time_s - trace[i].time_s;
    err_quadratic += glm::distance(quadratic.predict(dt).position, trace[i + 4].camera.position());
    err_linear += glm::distance(linear.predict(dt).position, trace[i + 4].camera.position());
  }
  std::cout << "[ info ] bicycle 4-frame position error: quadratic " << err_quadratic << ", line " << err_linear
            << "\n";
  EXPECT_LT(err_quadratic, 0.8 * err_linear);
}

}  // namespace
}  // namespace catgs
