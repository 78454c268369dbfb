// AdaptiveQuality's rule (session/adaptive_quality.h) on a made-up clock: down while poses are
// skipped, hold, up only when the cost would fit, refine once per stop.
#include <gtest/gtest.h>

#include "session/adaptive_quality.h"

namespace catgs::server {
namespace {

using Clock = AdaptiveQuality::Clock;
using std::chrono::milliseconds;

// Poses every `interval` ms for `ms` ms from `t`, every `replaced_every`-th one replacing an
// unrendered pose (0: none), a frame of `cost_ms` at the current level after each, and a tick
// every 250 ms. Returns the time after.
Clock::time_point drive(AdaptiveQuality& q, Clock::time_point t, int ms, int interval, int replaced_every,
                        double cost_ms) {
  for (int at = 0, n = 0; at < ms; at += interval, ++n) {
    const Clock::time_point now = t + milliseconds(at);
    q.on_pose(now, replaced_every > 0 && n % replaced_every == 0);
    q.on_frame(q.level(), cost_ms);
    if (at % 250 < interval) q.on_tick(now);
  }
  return t + milliseconds(ms);
}

TEST(AdaptiveQuality, StepsDownWhileSkippingAndHoldsBetweenSteps) {
  AdaptiveQuality q;
  Clock::time_point t{};
  // 60 Hz poses, every second one replaced (the server renders half of them).
  t = drive(q, t, 1100, 16, 2, 40.0);
  EXPECT_EQ(q.level(), 1);
  EXPECT_DOUBLE_EQ(q.scale(), 0.75);
  t = drive(q, t, 800, 16, 2, 40.0);  // within the 2 s hold
  EXPECT_EQ(q.level(), 1);
  t = drive(q, t, 1500, 16, 2, 40.0);
  EXPECT_EQ(q.level(), 2);
  t = drive(q, t, 5000, 16, 2, 40.0);
  EXPECT_EQ(q.level(), 2) << "0.5 is the lowest level";
}

TEST(AdaptiveQuality, FewSkipsDoNotStepDown) {
  AdaptiveQuality q;
  // One in ten replaced: under the 20% threshold.
  drive(q, Clock::time_point{}, 5000, 16, 10, 10.0);
  EXPECT_EQ(q.level(), 0);
}

// Link control (link_rate.h): while the link holds the bitrate down, skips are its doing and the
// bitrate answers them; the size steps down only once the link's cap is under the size's floor,
// and climbs only where the cap carries the level above.
TEST(AdaptiveQuality, ALimitingLinkStepsDownOnlyBelowTheFloor) {
  AdaptiveQuality q;
  q.on_link(/*limited=*/true, /*below_floor=*/false, /*fits_above=*/true);
  Clock::time_point t = drive(q, Clock::time_point{}, 3000, 16, 2, 40.0);
  EXPECT_EQ(q.level(), 0) << "half the poses skipped, but the link explains it";
  q.on_link(true, true, false);
  t = drive(q, t, 1100, 16, 2, 40.0);
  EXPECT_EQ(q.level(), 1);
  // Cheap frames and nothing skipped, but the cap would not carry full size: no climb.
  q.on_link(true, false, false);
  t = drive(q, t, 6000, 100, 0, 5.0);
  EXPECT_EQ(q.level(), 1);
  q.on_link(false, false, true);
  t = drive(q, t, 3100, 100, 0, 5.0);
  EXPECT_EQ(q.level(), 0);
}

TEST(AdaptiveQuality, ClimbsBackOnlyWhenTheCostWouldFit) {
  AdaptiveQuality q;
  Clock::time_point t = drive(q, Clock::time_point{}, 3500, 16, 2, 40.0);
  ASSERT_EQ(q.level(), 2);
  // 10 Hz, nothing skipped, but 50 ms frames: x2.25 at 0.75 is 112 ms, over 0.6 x 100 ms.
  t = drive(q, t, 6000, 100, 0, 50.0);
  EXPECT_EQ(q.level(), 2);
  // 20 ms frames: 45 ms at 0.75 fits; after 3 s there, 0.75 -> 1 (20 x 1.78 = 36 ms) too.
  t = drive(q, t, 3100, 100, 0, 20.0);
  EXPECT_EQ(q.level(), 1);
  t = drive(q, t, 3100, 100, 0, 20.0);
  EXPECT_EQ(q.level(), 0);
}

// Frames shown late with no pose skipped (the network or the decoder holds them): down while
// the client's median pose-to-shown latency passes max(150 ms, 4 pose intervals), no climb back
// while it does, and latencies under the limit change nothing.
TEST(AdaptiveQuality, LateFramesStepDownWithoutSkips) {
  const auto drive_latency = [](AdaptiveQuality& q, Clock::time_point t, int ms, double latency_ms) {
    for (int at = 0; at < ms; at += 16) {  // 60 Hz poses, none replaced, cheap frames
      const Clock::time_point now = t + milliseconds(at);
      q.on_pose(now, false);
      q.on_latency(now, latency_ms);
      q.on_frame(q.level(), 2.0);
      if (at % 250 < 16) q.on_tick(now);
    }
    return t + milliseconds(ms);
  };
  AdaptiveQuality fine, late;
  drive_latency(fine, Clock::time_point{}, 6000, 120.0);  // under 150 ms
  EXPECT_EQ(fine.level(), 0);
  Clock::time_point t = drive_latency(late, Clock::time_point{}, 1100, 400.0);
  EXPECT_EQ(late.level(), 1);
  t = drive_latency(late, t, 6000, 400.0);
  EXPECT_EQ(late.level(), 2) << "still late: down again after the hold, never up";
  // On time again: 2 ms frames fit (x2.25 at the level above: 4.5 ms, under 0.6 x 16 ms), so it
  // climbs back once the late latencies leave the window.
  t = drive_latency(late, t, 3100, 40.0);
  EXPECT_EQ(late.level(), 1);
}

TEST(AdaptiveQuality, ScaledSidesAreEvenAndAtLeast16) {
  EXPECT_EQ(AdaptiveQuality::scaled_side(1280, 0), 1280);
  EXPECT_EQ(AdaptiveQuality::scaled_side(1280, 1), 960);
  EXPECT_EQ(AdaptiveQuality::scaled_side(1280, 2), 640);
  EXPECT_EQ(AdaptiveQuality::scaled_side(718, 1), 538);  // 538.5 -> an even 538
  EXPECT_EQ(AdaptiveQuality::scaled_side(20, 2), 16);
  EXPECT_EQ(AdaptiveQuality::scaled_side(8, 2), 8);
}

}  // namespace
}  // namespace catgs::server
