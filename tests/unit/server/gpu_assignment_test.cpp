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
