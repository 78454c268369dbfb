// catgs-loadgen's report maths on known inputs: percentiles, rates, pooled totals, JSON, and
// the trace playback clock.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "loadgen/load_report.h"
#include "loadgen/load_session.h"

namespace {

using namespace catgs;
using namespace catgs::loadgen;

TEST(LoadReport, PercentileInterpolatesBetweenClosestRanks) {
  EXPECT_DOUBLE_EQ(percentile({4, 1, 3, 2}, 50), 2.5);
  EXPECT_DOUBLE_EQ(percentile({4, 1, 3, 2}, 0), 1);
  EXPECT_DOUBLE_EQ(percentile({4, 1, 3, 2}, 100), 4);
  EXPECT_DOUBLE_EQ(percentile({4, 1, 3, 2}, 95), 3.85);  // rank 2.85
  EXPECT_DOUBLE_EQ(percentile({7}, 99), 7);
  EXPECT_DOUBLE_EQ(percentile({}, 50), 0);
  std::vector<double> hundred;
  for (int i = 1; i <= 100; ++i) hundred.push_back(i);
  EXPECT_DOUBLE_EQ(percentile(hundred, 99), 99.01);
  EXPECT_DOUBLE_EQ(percentile(hundred, 50), 50.5);
  EXPECT_THROW(percentile({1}, 101), std::invalid_argument);
  EXPECT_THROW(percentile({1}, -1), std::invalid_argument);
}

SessionResult session(int index, std::uint64_t frames, double seconds, std::vector<double> latency) {
  SessionResult s;
  s.index = index;
  s.width = 64;
  s.height = 48;
  s.frames = frames;
  s.poses_sent = frames + 10;
  s.dropped = 10;
  s.bytes = 1000 * frames;
  s.run_seconds = seconds;
  s.latency_ms = std::move(latency);
  s.server.frames = frames;
  s.server.render = 2.0 * static_cast<double>(frames);
  s.server.render_key = frames / 2;
  return s;
}

TEST(LoadReport, TotalsPoolSessions) {
  const std::vector<SessionResult> run = {session(0, 100, 2.0, {10, 20, 30}), session(1, 30, 1.0, {40, 50})};
  const RunSummary t = summarize_run(run);
  EXPECT_EQ(t.sessions, 2);
  EXPECT_EQ(t.frames, 130u);
  EXPECT_EQ(t.dropped, 20u);
  EXPECT_DOUBLE_EQ(t.fps_total, 50.0 + 30.0);
  EXPECT_DOUBLE_EQ(t.fps_min, 30.0);
  EXPECT_DOUBLE_EQ(t.bytes_per_second, 50000.0 + 30000.0);
  EXPECT_DOUBLE_EQ(t.latency.p50, 30.0);  // pooled {10, 20, 30, 40, 50}
  EXPECT_DOUBLE_EQ(t.latency.max, 50.0);
  EXPECT_DOUBLE_EQ(t.latency.mean, 30.0);
  EXPECT_EQ(t.latency.samples, 5u);

  const nlohmann::json j = run_json(run);
  EXPECT_EQ(j["sessions"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["sessions"][0]["fps"].get<double>(), 50.0);
  EXPECT_DOUBLE_EQ(j["sessions"][1]["latency"]["p50_ms"].get<double>(), 45.0);
  EXPECT_DOUBLE_EQ(j["total"]["server"]["render_ms"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["total"]["server"]["render_key_fraction"].get<double>(), 0.5);
  EXPECT_EQ(j["total"]["frames"].get<int>(), 130);

  const std::string table = format_table(run);
  EXPECT_NE(table.find("total"), std::string::npos) << table;
  EXPECT_NE(table.find("64x48"), std::string::npos) << table;
  EXPECT_NE(table.find("80.0"), std::string::npos) << table;  // total FPS
}

TEST(LoadReport, TracePlaybackLoopsOnTheTraceClock) {
  Trace t(3);
  for (std::size_t i = 0; i < t.size(); ++i) {
    t[i].time_s = 0.5 * static_cast<double>(i);
    t[i].camera = Camera::from_pose(glm::vec3(static_cast<float>(i), 0, 0), glm::quat(1, 0, 0, 0), 60, 64, 48);
  }
  EXPECT_EQ(camera_at(t, 0.0).position().x, 0.0f);
  EXPECT_EQ(camera_at(t, 0.6).position().x, 1.0f);
  EXPECT_EQ(camera_at(t, 0.99).position().x, 1.0f);
  EXPECT_EQ(camera_at(t, 1.2).position().x, 0.0f);  // 1.2 mod 1.0 = 0.2
  EXPECT_EQ(camera_at(t, 1.55).position().x, 1.0f);
  EXPECT_EQ(camera_at(Trace(t.begin(), t.begin() + 1), 7.0).position().x, 0.0f);
}

}  // namespace
