// Pose prediction (issue 91, server/session/pose_prediction.h): a camera moving at a steady rate is
// drawn ahead by the delay its client reports, and by the wait for the display's refresh where
// that delay is short; jumps, repeats and a client that reports no delay are drawn as sent.
#include <gtest/gtest.h>

#include <glm/gtc/quaternion.hpp>

#include "session/pose_prediction.h"

namespace {

using catgs::server::CameraPose;
using catgs::server::PosePrediction;

// A camera sliding along x at 2 units/s and turning about y at 1 rad/s, sampled at time t_ms.
CameraPose moving(double t_ms) {
  CameraPose p;
  const float t = static_cast<float>(t_ms / 1000.0);
  p.position = {2.0f * t, 0.5f, -3.0f};
  p.orientation = glm::angleAxis(t, glm::vec3(0.0f, 1.0f, 0.0f));
  p.vertical_fov_deg = 50.0f;
  return p;
}

TEST(PosePrediction, ASteadyMotionIsDrawnAheadByTheReportedDelay) {
  PosePrediction p;
  for (int k = 0; k <= 30; ++k) p.on_pose(moving(k * 1000.0 / 60.0), k * 1000.0 / 60.0, k >= 10 ? 60.0 : 0.0);
  EXPECT_NEAR(p.lead_ms(), 60.0, 1e-9);  // a long delay: no refresh wait on top
  const double now = 30 * 1000.0 / 60.0;
  const CameraPose want = moving(now + 60.0), got = p.predicted();
  EXPECT_NEAR(got.position.x, want.position.x, 1e-3);
  EXPECT_NEAR(got.position.y, want.position.y, 1e-5);
  EXPECT_GT(std::abs(glm::dot(got.orientation, want.orientation)), 1.0f - 1e-6f);
  // Not the sent pose: 0.12 units and 0.06 rad ahead of it.
  EXPECT_GT(got.position.x - moving(now).position.x, 0.1f);
  EXPECT_EQ(got.vertical_fov_deg, 50.0f);
}

TEST(PosePrediction, NoReportedDelayJumpsAndRepeatsAreDrawnAsSent) {
  PosePrediction p;
  for (int k = 0; k <= 10; ++k) p.on_pose(moving(k * 10.0), k * 10.0, 0.0);
  EXPECT_EQ(p.predicted().position, moving(100.0).position);  // no delay reported: no lead
  p.on_pose(moving(110.0), 110.0, 80.0);
  EXPECT_NE(p.predicted().position, moving(110.0).position);  // now ahead
  p.on_pose(moving(110.0), 120.0, 0.0);                       // the same pose again: a stop
  EXPECT_EQ(p.predicted().position, moving(110.0).position);
  p.on_pose(moving(500.0), 500.0, 0.0);  // a jump 380 ms later (setPose, a hotspot)
  EXPECT_EQ(p.predicted().position, moving(500.0).position);
  EXPECT_EQ(p.predicted().orientation, moving(500.0).orientation);
}

TEST(PosePrediction, AShortDelayIsLedByTheDisplaysRefreshWaitTooTaperingToNoneAt40Ms) {
  const auto lead_for = [](double delay_ms, double display_hz) {
    PosePrediction p;
    p.on_pose(moving(0.0), 0.0, delay_ms, display_hz);
    return p.lead_ms();
  };
  EXPECT_NEAR(lead_for(8.0, 0.0), 8.0 + 500.0 / 60.0, 1e-9);          // loopback: half a 60 Hz refresh more
  EXPECT_NEAR(lead_for(16.0, 90.0), 16.0 + 500.0 / 90.0, 1e-9);       // a headset's own rate
  EXPECT_NEAR(lead_for(28.0, 0.0), 28.0 + 0.5 * 500.0 / 60.0, 1e-9);  // half way: half of it
  EXPECT_NEAR(lead_for(40.0, 0.0), 40.0, 1e-9);
  EXPECT_NEAR(lead_for(46.0, 0.0), 46.0, 1e-9);
  // No jump as a delay drifts across the taper: the lead rises with the delay.
  for (double d = 10.0; d < 50.0; d += 0.5) EXPECT_LE(lead_for(d, 0.0), lead_for(d + 0.5, 0.0) + 1e-9) << d;
  // And the pose is drawn that far ahead.
  PosePrediction p;
  for (int k = 0; k <= 30; ++k) p.on_pose(moving(k * 1000.0 / 60.0), k * 1000.0 / 60.0, k >= 10 ? 8.0 : 0.0);
  const double now = 30 * 1000.0 / 60.0;
  EXPECT_NEAR(p.predicted().position.x, moving(now + 8.0 + 500.0 / 60.0).position.x, 1e-3);
}

TEST(PosePrediction, TheLeadFollowsTheDelaySmoothlyAndStopsAtItsCeiling) {
  PosePrediction p;
  p.on_pose(moving(0.0), 0.0, 40.0);
  EXPECT_NEAR(p.lead_ms(), 40.0, 1e-9);  // the first report sets it
  p.on_pose(moving(16.0), 16.0, 140.0);  // one late frame moves it a fifth of the way
  EXPECT_NEAR(p.lead_ms(), 60.0, 1e-9);
  for (int k = 2; k < 100; ++k) p.on_pose(moving(16.0 * k), 16.0 * k, 5000.0);
  EXPECT_NEAR(p.lead_ms(), PosePrediction::kMaxLeadMs, 1e-6);
}

}  // namespace
