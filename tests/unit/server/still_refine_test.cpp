// The still view's refine frames (session/still_refine.h): at most kFrames per stop, only after
// kAfter with no pose, only when the last frame handed off was held back (smaller or under a rate
// cap); a second only after the first was handed off, held by the VBV's fill.
#include <gtest/gtest.h>

#include "session/still_refine.h"

namespace catgs::server {
namespace {

using Clock = StillRefine::Clock;
using std::chrono::milliseconds;

TEST(StillRefine, AfterTheCameraStoppedOnAHeldBackFrame) {
  static_assert(StillRefine::kFrames == 2);
  StillRefine r;
  const Clock::time_point t{};
  EXPECT_FALSE(r.take(t + milliseconds(5000))) << "no pose yet: nothing to refine";
  r.on_pose(t);
  r.on_frame(/*held_back=*/true, /*refine=*/false);
  EXPECT_FALSE(r.take(t + milliseconds(100))) << "the camera only just stopped";
  EXPECT_FALSE(r.take(t + StillRefine::kAfter - milliseconds(1))) << "a busy page's gap between poses";
  EXPECT_TRUE(r.take(t + StillRefine::kAfter));
  EXPECT_FALSE(r.take(t + milliseconds(600))) << "the first refine frame is not handed off yet";
  r.on_frame(/*held_back=*/false, /*refine=*/true, /*vbv_bound=*/true);
  EXPECT_TRUE(r.take(t + milliseconds(700))) << "the second, once the first was handed off, held by the VBV";
  r.on_frame(false, /*refine=*/true, /*vbv_bound=*/true);
  EXPECT_FALSE(r.take(t + milliseconds(2000))) << "two per stop at most";
  // The camera moves again and stops on a frame at the stream's best: nothing to refine.
  r.on_pose(t + milliseconds(3000));
  r.on_frame(/*held_back=*/false, false);
  EXPECT_FALSE(r.take(t + milliseconds(4000))) << "the last frame was not held back";
  // A held-back frame of the same stop comes later (frames in flight): now it is due.
  r.on_frame(/*held_back=*/true, false);
  EXPECT_TRUE(r.take(t + milliseconds(4000)));
}

TEST(StillRefine, OneWhenTheFirstReachedTheCrf) {
  StillRefine r;
  const Clock::time_point t{};
  r.on_pose(t);
  r.on_frame(true, false);
  ASSERT_TRUE(r.take(t + milliseconds(600)));
  r.on_frame(false, /*refine=*/true, /*vbv_bound=*/false);  // the VBV's fill had room
  EXPECT_FALSE(r.take(t + milliseconds(800)));
}

TEST(StillRefine, ARefineFrameIsNeverHeldBack) {
  StillRefine r;
  const Clock::time_point t{};
  r.on_pose(t);
  r.on_frame(true, false);
  ASSERT_TRUE(r.take(t + milliseconds(600)));
  r.on_frame(/*held_back=*/true, /*refine=*/true);  // encoded with no cap, whatever it says
  r.on_pose(t + milliseconds(700));                 // a new stop...
  EXPECT_FALSE(r.take(t + milliseconds(1300))) << "...whose last frame is a refine frame";
}

}  // namespace
}  // namespace catgs::server
