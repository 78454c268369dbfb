// Deadline-aware pacing (session/frame_pacing.h): the pose interval is measured from arrivals,
// a frame is skipped before encode only when it would miss its slot, a newer pose waits and can
// make its own slot, and never twice in a row.
#include <gtest/gtest.h>

#include "session/frame_pacing.h"

namespace {

using catgs::server::FramePacing;
using std::chrono::milliseconds;

TEST(FramePacing, SlotIsTwoMeasuredPoseIntervals) {
  FramePacing p;
  EXPECT_NEAR(p.deadline_ms(), 2 * 1000.0 / 60, 1e-9);  // before any pose: the browser's rate
  auto t = FramePacing::Clock::now();
  for (int i = 0; i < 200; ++i) p.on_pose(t += milliseconds(20));  // a 50 Hz client
  EXPECT_NEAR(p.pose_interval_ms(), 20.0, 0.05);
  p.on_pose(t += milliseconds(3000));  // the camera stopped for 3 s: a pause, not the rate
  p.on_pose(t += milliseconds(1));     // a burst
  EXPECT_NEAR(p.deadline_ms(), 40.0, 0.1);
}

TEST(FramePacing, SkipsALateFrameOnlyWhenANewerPoseWaitsAndCanMakeItsSlot) {
  FramePacing p;  // slot 33.3 ms at 60 poses/s
  p.on_encode(10.0);
  p.on_rendered(5.0);  // a pose is rendered 5 ms after it arrives: the next one can make it
  const auto t = FramePacing::Clock::now();
  EXPECT_FALSE(p.skip_before_encode(t, t + milliseconds(20), true));    // 20 + 10 < 33: in time
  EXPECT_FALSE(p.skip_before_encode(t, t + milliseconds(200), false));  // the newest pose
  EXPECT_TRUE(p.skip_before_encode(t, t + milliseconds(25), true));     // 25 + 10 > 33
  EXPECT_FALSE(p.skip_before_encode(t, t + milliseconds(25), true));    // not twice in a row
  EXPECT_TRUE(p.skip_before_encode(t, t + milliseconds(25), true));
  FramePacing slow;  // renders that take 40 ms: no frame could be in time, skipping would stall
  slow.on_encode(10.0);
  slow.on_rendered(40.0);
  EXPECT_FALSE(slow.skip_before_encode(t, t + milliseconds(60), true));
  FramePacing off(0);
  off.on_encode(10.0);
  off.on_rendered(1.0);
  EXPECT_FALSE(off.skip_before_encode(t, t + milliseconds(200), true));
}

}  // namespace
