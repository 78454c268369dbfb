// Motion predictor: exact on constant motion, robust to jitter, repeated and out-of-order stamps,
// stops, and useful on a real camera path.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "catgs/motion_predictor.h"
#include "catgs/speculation_planner.h"
#include "catgs/trace.h"
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

// A camera that speeds up: the fit over a shorter window lags less behind the current velocity
// (SpeculationParams::predictor_window_s), and the planner refuses a window outside (0, 1] s.
TEST(MotionPredictor, AShortWindowLagsLessOnAnAcceleratingCamera) {
  auto error_4_ahead = [](double window_s) {
    MotionPredictorParams params;
    params.fit_window_s = window_s;
    MotionPredictor mp(params);
    const float a = 4.0f;  // world units / s^2 along x
    auto at = [a](double t) {
      TimedPose p;
      p.time_s = t;
      p.position = glm::vec3(0.5f * a * static_cast<float>(t * t), 0.0f, 0.0f);
      return p;
    };
    for (int i = 0; i <= 24; ++i) mp.add(at(i / 120.0));
    return glm::distance(mp.predict(4 / 120.0).position, at(28 / 120.0).position);
  };
  const float long_fit = error_4_ahead(0.1), short_fit = error_4_ahead(0.017);
  std::cout << "[ info ] 4-frame error, accelerating: 100 ms fit " << long_fit << ", 17 ms fit " << short_fit << "\n";
  EXPECT_LT(short_fit, 0.5f * long_fit);
  SpeculationParams bad;
  bad.predictor_window_s = 0.0;
  EXPECT_THROW(SpeculationPlanner{bad}, std::invalid_argument);
  bad.predictor_window_s = 0.017;
  EXPECT_NO_THROW(SpeculationPlanner{bad});
}

}  // namespace
}  // namespace catgs
