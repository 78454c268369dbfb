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
  s.server.queue = 3.0 * static_cast<double>(frames);
  s.server.lane_wait = 1.0 * static_cast<double>(frames);
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
  EXPECT_DOUBLE_EQ(j["total"]["server"]["queue_ms"].get<double>(), 3.0);
  EXPECT_DOUBLE_EQ(j["total"]["server"]["lane_wait_ms"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(j["total"]["server"]["render_key_fraction"].get<double>(), 0.5);
  EXPECT_EQ(j["total"]["frames"].get<int>(), 130);

  const std::string table = format_table(run);
  EXPECT_NE(table.find("total"), std::string::npos) << table;

  // The renderer's stage times and lanes pool over sessions: frames 100 + 30 on lanes 0 and 1.
  std::vector<SessionResult> staged = run;
  staged[0].server.stage[2] = 100 * 0.5;  // keys 0.5 ms a frame
  staged[1].server.stage[2] = 30 * 1.15;  // 1.15 ms
  staged[0].server.lanes[0] = {60, 60 * 1.0};
  staged[0].server.lanes[1] = {40, 40 * 2.0};
  staged[1].server.lanes[1] = {30, 30 * 3.0};
  const nlohmann::json js = run_json(staged)["total"]["server"];
  EXPECT_DOUBLE_EQ(js["render_stages_ms"]["keys"].get<double>(), (50.0 + 34.5) / 130.0);
  EXPECT_DOUBLE_EQ(js["render_stages_ms"]["sort"].get<double>(), 0.0);
  ASSERT_EQ(js["render_lanes"].size(), 2u);
  EXPECT_EQ(js["render_lanes"][1]["lane"].get<int>(), 1);
  EXPECT_EQ(js["render_lanes"][1]["frames"].get<int>(), 70);
  EXPECT_DOUBLE_EQ(js["render_lanes"][1]["frame_ms_mean"].get<double>(), (80.0 + 90.0) / 70.0);
  EXPECT_NE(table.find("64x48"), std::string::npos) << table;
  EXPECT_NE(table.find("80.0"), std::string::npos) << table;  // total FPS
}

// A refused session is reported as refused: no "0x0 ... 0.0" row, no part in the slowest FPS,
// no PSNR that was never measured; skips (latest pose wins) and real drops stay apart.
TEST(LoadReport, RefusedSessionsSkipsAndUnmeasuredPsnr) {
  std::vector<SessionResult> run = {session(0, 100, 2.0, {10, 20}), session(1, 0, 0.0, {})};
  run[0].skipped = 7;
  run[0].dropped = 2;
  run[1].refused = true;
  run[1].refusal = "ERROR_SERVER_FULL: server full (1 sessions)";
  run[1].width = run[1].height = 0;
  run[1].poses_sent = run[1].dropped = 0;
  EXPECT_EQ(session_status(run[0]), "ok");
  EXPECT_EQ(session_status(run[1]), "refused");
  const RunSummary t = summarize_run(run);
  EXPECT_EQ(t.refused, 1);
  EXPECT_EQ(t.failed, 0);
  EXPECT_DOUBLE_EQ(t.fps_min, 50.0);  // not 0: the refused session did not run
  EXPECT_EQ(t.skipped, 7u);
  EXPECT_EQ(t.dropped, 2u);

  const std::string table = format_table(run);
  EXPECT_NE(table.find("1        refused by the server: ERROR_SERVER_FULL: server full (1 sessions)"),
            std::string::npos)
      << table;
  EXPECT_EQ(table.find("0x0"), std::string::npos) << table;
  EXPECT_NE(table.find("skipped dropped"), std::string::npos) << table;
  EXPECT_NE(table.find("1 ran cleanly, 1 refused, 0 failed"), std::string::npos) << table;

  nlohmann::json j = run_json(run);
  EXPECT_EQ(j["sessions"][1]["status"], "refused");
  EXPECT_EQ(j["sessions"][1]["refusal"], run[1].refusal);
  EXPECT_EQ(j["sessions"][0]["skipped"].get<int>(), 7);
  EXPECT_EQ(j["sessions"][0]["dropped"].get<int>(), 2);
  EXPECT_EQ(j["total"]["refused"].get<int>(), 1);
  EXPECT_TRUE(j["sessions"][0]["psnr_mean_db"].is_null()) << "no frame was checked";
  EXPECT_TRUE(j["sessions"][0]["psnr_min_db"].is_null());

  run[0].checked = 3;
  run[0].psnr_min = 31.5;
  run[0].psnr_mean = 33.25;
  j = run_json(run);
  EXPECT_DOUBLE_EQ(j["sessions"][0]["psnr_mean_db"].get<double>(), 33.25);
  EXPECT_DOUBLE_EQ(j["sessions"][0]["psnr_min_db"].get<double>(), 31.5);

  // A session that ran without a frame, or with errors, failed.
  SessionResult none = session(2, 0, 1.0, {});
  EXPECT_EQ(session_status(none), "failed");
  SessionResult lost = session(3, 10, 1.0, {});
  lost.errors = 1;
  EXPECT_EQ(session_status(lost), "failed");
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
