// The render scheduler: sessions take turns (one job per session per round, not one FIFO of
// requests) and the pixels rendering at once stay within the cap (issue 22, finding 5).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "render/render_scheduler.h"

namespace {

using catgs::server::RenderScheduler;
using Clock = std::chrono::steady_clock;

TEST(RenderScheduler, SessionsTakeTurns) {
  RenderScheduler s;
  std::mutex mutex;
  std::vector<int> order;
  auto job = [&](int owner) {
    return [&, owner] {
      std::lock_guard<std::mutex> lock(mutex);
      order.push_back(owner);
    };
  };
  // Session 1 floods first, then 2 and 3 ask: a FIFO would serve 1 four times before anyone else.
  for (int k = 0; k < 4; ++k) s.post(1, 100, job(1));
  for (int k = 0; k < 2; ++k) s.post(2, 100, job(2));
  s.post(3, 100, job(3));
  s.start(1, 1000);
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  EXPECT_EQ(order, (std::vector<int>{1, 2, 3, 1, 2, 1, 1}));
}

TEST(RenderScheduler, PixelsInFlightStayWithinTheCap) {
  RenderScheduler s;
  std::atomic<long long> now_pixels{0}, peak{0};
  std::atomic<int> ran{0};
  auto job = [&](long long pixels) {
    return [&, pixels] {
      const long long p = now_pixels += pixels;
      for (long long seen = peak.load(); p > seen && !peak.compare_exchange_weak(seen, p);) {}
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      now_pixels -= pixels;
      ran++;
    };
  };
  s.start(4, 100);
  for (int owner = 0; owner < 6; ++owner) s.post(static_cast<RenderScheduler::Owner>(owner), 60, job(60));
  s.post(9, 250, job(250));  // over the cap on its own: runs, alone
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  EXPECT_EQ(ran.load(), 7);
  EXPECT_EQ(peak.load(), 250) << "4 lanes, but 60-pixel jobs must not run two at once under a cap of 100";
  EXPECT_EQ(s.pixels_in_flight(), 0);
}

TEST(RenderScheduler, MoveOnlyJobsAndPollAfterStop) {
  RenderScheduler s;
  s.start(1, 10);
  s.stop();
  auto value = std::make_unique<int>(7);
  int seen = 0;
  s.post(1, 1, [&seen, value = std::move(value)] { seen = *value; });
  EXPECT_EQ(s.queued(), 1u);
  EXPECT_EQ(s.poll(), 1u);
  EXPECT_EQ(seen, 7);
}

}  // namespace
