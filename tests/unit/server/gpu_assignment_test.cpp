// --gpus: parsing the device list, and sessions spread over the GPUs by count (gpu_assignment.h);
// the per-GPU series of /metrics.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "render/gpu_assignment.h"
#include "process/server_metrics.h"

namespace catgs::server {
namespace {

TEST(Gpus, ParsesAllAndLists) {
  EXPECT_EQ(parse_gpus("all", 2), (std::vector<int>{0, 1}));
  EXPECT_EQ(parse_gpus("1", 2), (std::vector<int>{1}));
  EXPECT_EQ(parse_gpus("3,0", 4), (std::vector<int>{3, 0}));
}

TEST(Gpus, RefusesWhatIsNotThere) {
  auto message = [](const std::string& spec, int visible) {
    try {
      parse_gpus(spec, visible);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message("2", 2).find("device 2 is not visible (2 visible: 0..1)"), std::string::npos);
  EXPECT_NE(message("0,0", 2).find("listed twice"), std::string::npos);
  EXPECT_NE(message("0,x", 2).find("'x' is not a device number"), std::string::npos);
  EXPECT_NE(message("-1", 2).find("not a device number"), std::string::npos);
  EXPECT_NE(message("0,", 2).find("'' is not a device number"), std::string::npos);
  EXPECT_NE(message(",0", 2).find("'' is not a device number"), std::string::npos);
  EXPECT_NE(message("all", 0).find("no CUDA device is visible"), std::string::npos);
}

TEST(Gpus, SessionsGoToTheGpuWithFewest) {
  GpuAssignment g({1, 0});
  EXPECT_EQ(g.acquire(), 1);  // a tie: the first listed
  EXPECT_EQ(g.acquire(), 0);
  EXPECT_EQ(g.acquire(), 1);
  EXPECT_EQ(g.sessions(), (std::vector<std::int64_t>{2, 1}));
  g.release(1);
  g.release(1);
  EXPECT_EQ(g.acquire(), 1);  // device 1 now has 0 sessions, device 0 one
  g.release(7);               // not one of ours: ignored
  EXPECT_EQ(g.sessions(), (std::vector<std::int64_t>{1, 1}));
  GpuAssignment none({});
  EXPECT_EQ(none.acquire(), -1);
}

TEST(Gpus, SessionsArePlacedOnlyWhereTheirMemoryFits) {
  constexpr std::uint64_t GiB = 1ull << 30;
  GpuAssignment g({0, 1}, {10 * GiB, 4 * GiB});
  auto scene0 = g.add_scene(0, 6 * GiB);  // GPU 0 holds a big scene: 4 GiB left; GPU 1 all 4
  auto scene1 = g.add_scene(1, 1 * GiB);  // 3 GiB left
  const GpuAssignment::Placement a = g.place(3 * GiB);
  EXPECT_TRUE(a.placed);
  EXPECT_EQ(a.device, 0);  // a tie on sessions: the first listed
  const GpuAssignment::Placement b = g.place(3 * GiB);
  EXPECT_TRUE(b.placed);
  EXPECT_EQ(b.device, 1);                               // fewest sessions with room
  const GpuAssignment::Placement c = g.place(2 * GiB);  // 1 GiB left on GPU 0, 0 on GPU 1
  EXPECT_FALSE(c.placed);
  EXPECT_NE(c.why.find("no GPU can hold another session (2.0 GiB needed; gpu 0: 1.0 GiB free of 10.0 GiB by the "
                       "server's accounting, 1 sessions; gpu 1: 0 MiB free of 4.0 GiB by the server's accounting, "
                       "1 sessions)"),
            std::string::npos)
      << c.why;
  EXPECT_FALSE(c.driver_binds) << "no probe: the accounting alone";
  EXPECT_EQ(g.sessions(), (std::vector<std::int64_t>{1, 1})) << "a refusal changes nothing";
  EXPECT_EQ(g.largest_room(), 1 * GiB);
  // A session's buffers grew past its estimate: applied, and said to be over the capacity.
  EXPECT_FALSE(g.update(0, 3 * GiB, 5 * GiB));
  EXPECT_EQ(g.memory()[0].reserved, 5 * GiB);
  EXPECT_TRUE(g.update(0, 5 * GiB, 3 * GiB));
  // The scene on GPU 1 unloads: its room comes back.
  scene1.reset();
  EXPECT_EQ(g.memory()[1].scenes, 0u);
  EXPECT_EQ(g.memory()[1].room(), 1 * GiB);
  EXPECT_EQ(g.place(1 * GiB).device, 0);  // 1 GiB free on each, one session each: the first listed
  g.release(0, 3 * GiB);
  EXPECT_EQ(g.memory()[0].reserved, 1 * GiB);
  EXPECT_EQ(g.memory()[0].sessions, 1);
}

// Another process holds memory (issue 73): the driver's free bytes, less the reserve and what
// the sessions may still grow into (reservation less what their buffers hold), bound the room
// where they are less than the accounting's; the refusal and largest_room say which binds.
TEST(Gpus, WhatTheDriverReportsFreeBindsWhereAnotherProcessHoldsMemory) {
  constexpr std::uint64_t GiB = 1ull << 30;
  std::uint64_t free_bytes[2] = {70 * GiB, 70 * GiB};
  int probes = 0;
  GpuAssignment g(
      {0, 1}, {78 * GiB, 78 * GiB},
      [&](int device) {
        ++probes;
        return free_bytes[device];
      },
      2 * GiB);
  auto scene = g.add_scene(0, 10 * GiB);
  // Nothing else on the GPUs: the accounting binds on GPU 0 (68 GiB) and the driver on GPU 1
  // (68 GiB too: 70 free less the reserve); placed by session count.
  const GpuAssignment::Placement a = g.place(4 * GiB);
  ASSERT_TRUE(a.placed);
  EXPECT_GT(probes, 0) << "the door reads the driver";
  EXPECT_EQ(g.memory()[0].driver_free, 70 * GiB);
  // A hog takes GPU 1 down to 5 GiB free and GPU 0 to 9 GiB: the session on GPU 0 holds 1 GiB of
  // its 4 GiB reservation, so 3 GiB of GPU 0's free memory is still its own.
  free_bytes[0] = 9 * GiB;
  free_bytes[1] = 5 * GiB;
  g.hold(a.device, 0, 1 * GiB);
  EXPECT_EQ(g.memory()[0].held, 1 * GiB);
  EXPECT_EQ(g.memory()[0].driver_room(2 * GiB), 4 * GiB);  // 9 - 2 reserve - 3 still to come
  EXPECT_EQ(g.memory()[1].driver_room(2 * GiB), 3 * GiB);
  std::string binds;
  EXPECT_EQ(g.largest_room(&binds), 4 * GiB);
  EXPECT_EQ(binds, "driver");
  const GpuAssignment::Placement b = g.place(5 * GiB);  // the accounting has 64 and 78 GiB
  EXPECT_FALSE(b.placed);
  EXPECT_TRUE(b.driver_binds);
  EXPECT_NE(b.why.find("gpu 1: 78.0 GiB free of 78.0 GiB by the server's accounting, 3.0 GiB by the driver (5.0 GiB "
                       "free, less the 2.0 GiB reserve and 0 MiB its sessions may still take): the driver binds"),
            std::string::npos)
      << b.why;
  const GpuAssignment::Placement c = g.place(3 * GiB);  // fits GPU 1 by the driver
  ASSERT_TRUE(c.placed);
  EXPECT_EQ(c.device, 1);
  // The hog leaves: the accounting binds again.
  free_bytes[0] = free_bytes[1] = 80 * GiB;
  EXPECT_EQ(g.largest_room(&binds), 78 * GiB - 3 * GiB);
  EXPECT_EQ(binds, "accounting");
  g.release(a.device, 4 * GiB, 1 * GiB);
  EXPECT_EQ(g.memory()[0].held, 0u);
  EXPECT_EQ(g.memory()[0].reserved, 0u);
}

TEST(Gpus, TheCpuRenderersHostSlotHoldsTheAllowance) {
  GpuAssignment unlimited({});
  EXPECT_EQ(unlimited.place(1ull << 40).device, -1);
  EXPECT_TRUE(unlimited.place(1ull << 40).placed);
  EXPECT_EQ(unlimited.sessions(), std::vector<std::int64_t>{}) << "no GPUs: no per-GPU counts";
  GpuAssignment host({}, {1000});
  auto scene = host.add_scene(-1, 400);
  EXPECT_TRUE(host.place(500).placed);
  const GpuAssignment::Placement full = host.place(200);
  EXPECT_FALSE(full.placed);
  EXPECT_NE(full.why.find("no device-memory allowance can hold another session"), std::string::npos) << full.why;
  host.release(-1, 500);
  EXPECT_TRUE(host.place(200).placed);
}

TEST(Gpus, MetricsCarryAGpuLabel) {
  ServerMetrics m;
  EXPECT_EQ(m.prometheus_text().find("catgs_gpu_sessions"), std::string::npos);  // no GPUs: no series
  GpuAssignment g({0, 1});
  g.acquire();
  m.set_gpus(g.devices(), [&g] { return g.sessions(); });
  m.observe_gpu_render(1, 0.002);
  m.observe_gpu_render(5, 0.002);  // not one of ours: ignored
  const std::string text = m.prometheus_text();
  EXPECT_NE(text.find("catgs_gpu_sessions{gpu=\"0\"} 1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("catgs_gpu_sessions{gpu=\"1\"} 0\n"), std::string::npos);
  EXPECT_NE(text.find("catgs_gpu_render_seconds_count{gpu=\"1\"} 1\n"), std::string::npos);
  EXPECT_NE(text.find("catgs_gpu_render_seconds_count{gpu=\"0\"} 0\n"), std::string::npos);
}

}  // namespace
}  // namespace catgs::server
