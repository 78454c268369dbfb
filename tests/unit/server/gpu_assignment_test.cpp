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
  EXPECT_NE(c.why.find("no GPU can hold another session (2.0 GiB needed; gpu 0: 1.0 GiB free of 10.0 GiB, 1 sessions;"
                       " gpu 1: 0 MiB free of 4.0 GiB, 1 sessions)"),
            std::string::npos)
      << c.why;
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
