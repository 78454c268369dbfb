// The render scheduler: sessions take turns (one job per session per round, not one FIFO of
// requests) and the pixels rendering at once stay within the cap (issue 22, finding 5).
#include <gtest/gtest.h>

#include <atomic>
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <fstream>
#include <vector>

#include "render/render_scheduler.h"
#include "process/thread_name.h"
#include "server_options.h"

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

// A job knows its lane (FrameTimings.render_lane): each of 3 lanes' index, never another, and
// -1 on a thread that is not a lane.
TEST(RenderScheduler, JobsKnowTheirLane) {
  RenderScheduler s;
  std::mutex mutex;
  std::vector<int> seen;
  for (int k = 0; k < 30; ++k)
    s.post(static_cast<RenderScheduler::Owner>(k), 1, [&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));  // the lanes overlap
      std::lock_guard<std::mutex> lock(mutex);
      seen.push_back(RenderScheduler::current_lane());
    });
  s.start(3, 1000);
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  ASSERT_EQ(seen.size(), 30u);
  for (int lane : seen) EXPECT_TRUE(lane >= 0 && lane < 3) << lane;
  EXPECT_GT(std::set<int>(seen.begin(), seen.end()).size(), 1u) << "more than one lane ran";
  EXPECT_EQ(RenderScheduler::current_lane(), -1);
}

// --gpu-wait: how a lane waits for its GPU; block by default, spin on request, nothing else.
TEST(RenderScheduler, GpuWaitOption) {
  const char* none[] = {"catgs-server"};
  catgs::server::ServerOptions o0;
  ASSERT_TRUE(catgs::server::parse_server_options(1, const_cast<char**>(none), o0));
  EXPECT_EQ(o0.render.gpu_wait, "block");
  const char* spin[] = {"catgs-server", "--gpu-wait", "spin"};
  catgs::server::ServerOptions o1;
  ASSERT_TRUE(catgs::server::parse_server_options(3, const_cast<char**>(spin), o1));
  EXPECT_EQ(o1.render.gpu_wait, "spin");
  const char* bad[] = {"catgs-server", "--gpu-wait", "yield"};
  catgs::server::ServerOptions o2;
  EXPECT_THROW((void)catgs::server::parse_server_options(3, const_cast<char**>(bad), o2), std::invalid_argument);
}

// Frames in flight: a job that returns a Finish leaves its frame begun; the lane takes the next
// job while it holds fewer than frames_per_lane, and finishes the oldest first otherwise or when
// nothing may start. `frames` 1 is the old lane: each job finished before the next. `ready`: the
// finishes say their frames are done already (Finish::ready), so each goes before the next begin.
std::vector<std::string> lane_trace(int frames_per_lane, std::int64_t pixels, std::int64_t cap, bool ready = false) {
  RenderScheduler s;
  s.set_frames_per_lane(frames_per_lane);
  std::mutex mutex;
  std::vector<std::string> trace;
  auto note = [&](std::string what) {
    std::lock_guard<std::mutex> lock(mutex);
    trace.push_back(std::move(what));
  };
  for (int owner = 1; owner <= 3; ++owner)
    s.post(static_cast<RenderScheduler::Owner>(owner), pixels, [&, owner] {
      note("begin " + std::to_string(owner));
      return RenderScheduler::Finish::of([&, owner] { note("finish " + std::to_string(owner)); },
                                         [ready] { return ready; });
    });
  s.start(1, cap);
  EXPECT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  return trace;
}

TEST(RenderScheduler, ALaneKeepsFramesInFlight) {
  using V = std::vector<std::string>;
  EXPECT_EQ(lane_trace(2, 10, 1000), (V{"begin 1", "begin 2", "finish 1", "begin 3", "finish 2", "finish 3"}));
  EXPECT_EQ(lane_trace(3, 10, 1000), (V{"begin 1", "begin 2", "begin 3", "finish 1", "finish 2", "finish 3"}));
  EXPECT_EQ(lane_trace(1, 10, 1000), (V{"begin 1", "finish 1", "begin 2", "finish 2", "begin 3", "finish 3"}));
  // A begun frame's pixels count until its finish: two of 60 do not fit a cap of 100.
  EXPECT_EQ(lane_trace(2, 60, 100), (V{"begin 1", "finish 1", "begin 2", "finish 2", "begin 3", "finish 3"}));
  // A frame done on the GPU is finished before the next begins, however many the lane may hold.
  EXPECT_EQ(lane_trace(3, 10, 1000, true), (V{"begin 1", "finish 1", "begin 2", "finish 2", "begin 3", "finish 3"}));
}

// drain() returns once every finish has run, and stop() finishes the frames a lane holds.
TEST(RenderScheduler, DrainAndStopWaitForFinishes) {
  for (const bool drain_first : {true, false}) {
    RenderScheduler s;
    s.set_frames_per_lane(4);
    std::atomic<int> begun{0}, finished{0};
    for (int owner = 1; owner <= 4; ++owner)
      s.post(static_cast<RenderScheduler::Owner>(owner), 1, [&] {
        ++begun;
        return RenderScheduler::Finish::of([&] {
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
          ++finished;
        });
      });
    s.start(1, 1000);
    if (drain_first) {
      ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
      EXPECT_EQ(finished.load(), 4);
    } else {
      while (begun.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    s.stop();
    EXPECT_EQ(finished.load(), begun.load()) << "drain first: " << drain_first;
  }
}

// A finish that throws is logged; the lane goes on.
TEST(RenderScheduler, AThrowingFinishLeavesTheLaneRunning) {
  RenderScheduler s;
  s.set_frames_per_lane(2);
  std::atomic<int> ran{0};
  s.post(1, 1, [] { return RenderScheduler::Finish::of([]() -> void { throw std::runtime_error("boom"); }); });
  s.post(2, 1, [&] { ++ran; });
  s.start(1, 1000);
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  EXPECT_EQ(ran.load(), 1);
}

// The kernel's name of the calling thread (/proc/thread-self/comm, without its newline).
std::string kernel_thread_name() {
  std::ifstream in("/proc/thread-self/comm");
  std::string name;
  std::getline(in, name);
  return name;
}

// Each lane names its thread "catgs-laneN" (process/thread_name.h), as a host profile shows it;
// a name past the kernel's 15 characters is cut, not refused.
TEST(RenderScheduler, LanesAreNamedThreads) {
  catgs::server::RenderScheduler s;
  std::mutex m;
  std::set<std::string> names;
  for (int i = 0; i < 8; ++i)
    s.post(static_cast<catgs::server::RenderScheduler::Owner>(i), 1, [&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      std::lock_guard<std::mutex> lock(m);
      names.insert(kernel_thread_name());
    });
  s.start(2, 1 << 20);
  ASSERT_TRUE(s.drain(std::chrono::steady_clock::now() + std::chrono::seconds(10)));
  s.stop();
  for (const std::string& n : names) EXPECT_TRUE(n == "catgs-lane0" || n == "catgs-lane1") << n;
  EXPECT_FALSE(names.empty());

  std::string cut;
  std::thread t([&] {
    catgs::server::name_this_thread("catgs-a-very-long-thread-name");
    cut = kernel_thread_name();
  });
  t.join();
  EXPECT_EQ(cut, "catgs-a-very-lo");
}

// --frames-per-lane: 2 with the CUDA renderer, 1 with the CPU one, a given count wins; 0 (the
// renderer's default) to 16.
TEST(RenderScheduler, FramesPerLaneOption) {
  EXPECT_EQ(RenderScheduler::default_frames_per_lane(0, "cuda"), 2);
  EXPECT_EQ(RenderScheduler::default_frames_per_lane(0, "cpu"), 1);
  EXPECT_EQ(RenderScheduler::default_frames_per_lane(3, "cpu"), 3);
  const char* three[] = {"catgs-server", "--frames-per-lane", "3"};
  catgs::server::ServerOptions o;
  ASSERT_TRUE(catgs::server::parse_server_options(3, const_cast<char**>(three), o));
  EXPECT_EQ(o.render.frames_per_lane, 3);
  const char* zero[] = {"catgs-server", "--frames-per-lane", "0"};  // the renderer's default, as --render-lanes 0
  catgs::server::ServerOptions oz;
  ASSERT_TRUE(catgs::server::parse_server_options(3, const_cast<char**>(zero), oz));
  EXPECT_EQ(oz.render.frames_per_lane, 0);
  for (const char* v : {"-1", "17"}) {
    const char* bad[] = {"catgs-server", "--frames-per-lane", v};
    catgs::server::ServerOptions ob;
    EXPECT_THROW((void)catgs::server::parse_server_options(3, const_cast<char**>(bad), ob), std::invalid_argument) << v;
  }
}

// The shared stage 1 was removed (docs/DESIGN.md "Render scheduler"): its --shared-stage1 is an
// unknown option now, refused as any other.
TEST(RenderScheduler, SharedStage1OptionIsGone) {
  const char* shared[] = {"catgs-server", "--shared-stage1", "4"};
  catgs::server::ServerOptions o;
  EXPECT_THROW((void)catgs::server::parse_server_options(3, const_cast<char**>(shared), o), std::invalid_argument);
}

// Video export frames (post_background) run only when no session's job is queued: posted first,
// they still go after every live job, and an export that posts its next frame after each one
// (as session/session_export.cpp does) lets the live jobs queued meanwhile go first.
TEST(RenderScheduler, BackgroundJobsYieldToLiveJobs) {
  RenderScheduler s;
  std::mutex mutex;
  std::vector<int> order;  // 0: a background job, else the live owner
  auto record = [&](int who) {
    std::lock_guard<std::mutex> lock(mutex);
    order.push_back(who);
  };
  s.post_background(7, 100, [&] { record(0); });
  s.post_background(7, 100, [&] { record(0); });
  s.post(1, 100, [&] { record(1); });
  s.post(2, 100, [&] { record(2); });
  s.post(1, 100, [&] { record(1); });
  s.start(1, 1000);
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  EXPECT_EQ(order, (std::vector<int>{1, 2, 1, 0, 0}));

  // A self-reposting export: each of its frames queues a live job, which runs before its next frame.
  order.clear();
  std::function<void(int)> frame = [&](int left) {
    record(0);
    s.post(3, 100, [&] { record(3); });
    if (left > 1) s.post_background(7, 100, [&frame, left] { frame(left - 1); });
  };
  s.post_background(7, 100, [&frame] { frame(3); });
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
  s.stop();
  EXPECT_EQ(order, (std::vector<int>{0, 3, 0, 3, 0, 3}));
}

// With several lanes, one stays free for live work: background jobs never take the last one. The
// background jobs here hold their lanes until the live job has run: were no lane left for it,
// they would wait out their 5 s and say so.
TEST(RenderScheduler, BackgroundJobsLeaveALaneForLiveWork) {
  RenderScheduler s;
  std::mutex mutex;
  std::condition_variable live_ran;
  bool live_done = false;
  int background_now = 0, background_peak = 0, timed_out = 0;
  auto blocking = [&] {
    std::unique_lock<std::mutex> lock(mutex);
    background_peak = std::max(background_peak, ++background_now);
    if (!live_ran.wait_for(lock, std::chrono::seconds(5), [&] { return live_done; })) timed_out++;
    background_now--;
  };
  for (int k = 0; k < 4; ++k) s.post_background(static_cast<RenderScheduler::Owner>(k), 10, blocking);
  s.start(3, 1000);
  while (true) {  // both lanes the background may have are taken
    std::lock_guard<std::mutex> lock(mutex);
    if (background_now == 2) break;
  }
  s.post(1, 10, [&] {
    std::lock_guard<std::mutex> lock(mutex);
    live_done = true;
    live_ran.notify_all();
  });
  ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(20)));
  s.stop();
  EXPECT_EQ(timed_out, 0) << "the live job did not get the lane left for it";
  EXPECT_EQ(background_peak, 2) << "3 lanes: at most 2 background jobs at once";
}

// A background job also waits while a live job runs (it would share the device with it), up to
// the yield; then it runs beside it, so that a busy server still exports.
TEST(RenderScheduler, BackgroundJobsWaitForAGapUpToTheYield) {
  for (const bool long_yield : {true, false}) {
    SCOPED_TRACE(long_yield ? "yield 20 s: waits for the live job" : "yield 30 ms: runs beside it");
    RenderScheduler s;
    s.set_background_yield(std::chrono::milliseconds(long_yield ? 20000 : 30));
    std::mutex mutex;
    std::condition_variable changed;
    bool live_started = false, background_ran = false, release = false, ran_beside = false;
    s.start(3, 1000);
    s.post(1, 10, [&] {
      std::unique_lock<std::mutex> lock(mutex);
      live_started = true;
      changed.notify_all();
      // Held until the test releases it, or (short yield) until the background job has run.
      changed.wait_for(lock, std::chrono::seconds(5), [&] { return release || background_ran; });
      ran_beside = background_ran;
    });
    {
      std::unique_lock<std::mutex> lock(mutex);
      changed.wait(lock, [&] { return live_started; });
    }
    s.post_background(7, 10, [&] {
      std::lock_guard<std::mutex> lock(mutex);
      background_ran = true;
      changed.notify_all();
    });
    if (long_yield) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      std::lock_guard<std::mutex> lock(mutex);
      EXPECT_FALSE(background_ran) << "it ran beside a live job within its yield";
      release = true;
      changed.notify_all();
    }
    ASSERT_TRUE(s.drain(Clock::now() + std::chrono::seconds(10)));
    s.stop();
    EXPECT_TRUE(background_ran);
    EXPECT_EQ(ran_beside, !long_yield);
  }
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
