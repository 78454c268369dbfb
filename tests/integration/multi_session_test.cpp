// Several sessions at once (issue 5): different traces and frame sizes, all with correct frames
// under the catgs pipeline; sessions that leave mid-stream free everything; the encoder flags;
// catgs-loadgen against the real server.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <sched.h>

#include <algorithm>
#include <functional>
#include <memory>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <mutex>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "process/first_view.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "server_process.h"
#include "stream_checks.h"

namespace {

using namespace catgs;
using namespace catgs::itest;
using loadgen::pose_from_camera;
using loadgen::StreamClient;
using loadgen::VideoDecoder;
using Clock = std::chrono::steady_clock;

const std::string kTrainCams = kDataDir + "/traces/tandt_train.cameras.json";

// One session's stream: poses stamped at 120 Hz on the client clock, sent in lock step; every
// frame must answer its pose and decode to the CPU render of it. Returns the session's last
// Stats; failures go to gtest (thread-safe) tagged with `name`.
pb::Stats stream_and_check(int port, const std::string& name, const Trace& trace, int w, int h) {
  SCOPED_TRACE(name);
  StreamClient c;
  c.connect(port);
  const pb::Welcome welcome = c.hello(w, h);
  EXPECT_EQ(welcome.pipeline(), "catgs");
  VideoDecoder dec;
  cpu::CpuRenderer ref(load_model(kBiker), RenderOptions{});
  const double t0 = now_ms();
  double worst = 1e9;
  for (std::uint32_t i = 0; i < trace.size(); ++i) {
    const pb::Pose pose = pose_from_camera(trace[i].camera, i, t0 + i * 1000.0 / 120.0);
    c.send_pose(pose);
    auto m = wait_for(c, 30000, [](const pb::ServerMessage& s) { return s.has_frame() || s.has_error(); });
    if (!m || !m->has_frame()) {
      ADD_FAILURE() << name << ": no frame for pose " << i;
      return {};
    }
    EXPECT_EQ(m->frame().pose_sequence(), i);
    EXPECT_EQ(m->frame().width(), static_cast<std::uint32_t>(w));
    const double psnr = frame_psnr(dec, ref, m->frame(), pose);
    EXPECT_GE(psnr, 30.0) << name << " frame " << i;
    // x264's own measure of its picture came with the frame (the unit test holds it equal to a
    // decoder's).
    EXPECT_GT(m->frame().timings().encode_psnr_db(), 30.0f) << name << " frame " << i;
    worst = std::min(worst, psnr);
  }
  auto stats = wait_for(c, 3000, [](const pb::ServerMessage& s) { return s.has_stats(); });
  if (!stats) {
    ADD_FAILURE() << name << ": no Stats";
    return {};
  }
  EXPECT_GT(stats->stats().encode_psnr_db_mean(), 30.0);
  EXPECT_EQ(stats->stats().encoder().rfind("x264 ", 0), 0u) << stats->stats().encoder();
  std::cout << "[ info ] " << name << " " << w << "x" << h << ": " << trace.size() << " frames, worst PSNR " << worst
            << " dB, " << stats->stats().key_frames() << " key frames, " << stats->stats().sub_frames()
            << " sub-frames\n";
  c.ws().close();
  return stats->stats();
}

// Three sessions at once: a slow orbit, a real camera path (tandt_train's cameras.json moved onto
// the scene; a fly-over without real data) and a zoom, at three frame sizes; `extra`: more server
// flags.
void three_sessions_get_correct_frames(const std::vector<std::string>& extra) {
  std::vector<std::string> flags = {"--pipeline", "catgs", "--threads", "3"};
  flags.insert(flags.end(), extra.begin(), extra.end());
  ServerProcess server(server_args(kBiker, flags));
  const auto model = load_model(kBiker);
  const Bounds rb = robust_bounds(*model);
  const float r = 1.4f * glm::length(model->bounds().extent());
  const int kFrames = 10;
  GeneratorParams g;
  g.rate_hz = 120.0;
  g.duration_s = (kFrames - 1) / g.rate_hz;
  g.fov_deg = 50.0f;

  struct Run {
    std::string name;
    int w, h;
    Trace trace;
  };
  std::vector<Run> runs;
  g.width = 320;
  g.height = 240;
  runs.push_back(
      {"orbit", 320, 240, make_orbit(model->bounds(), r, 0.2f * r, 30.0f * static_cast<float>(g.duration_s), g)});
  if (std::filesystem::exists(kTrainCams)) {
    Trace real =
        fit_trace_to_scene(load_inria_cameras(kTrainCams), *model, estimate_up(*model), 0.6f, 120.0, 0.5, 256, 192);
    real.resize(kFrames);
    runs.push_back({"real path (tandt_train)", 256, 192, real});
  } else {
    std::cout << "[ info ] " << kTrainCams << " not found: a fly-over stands in for the real path\n";
    g.width = 256;
    g.height = 192;
    runs.push_back({"fly-over", 256, 192,
                    make_flyover(rb.center() + glm::vec3(-r, -0.5f * r, 0),
                                 rb.center() + glm::vec3(-0.9f * r, -0.5f * r, 0), 20.0f, g)});
  }
  g.width = 192;
  g.height = 144;
  runs.push_back({"zoom", 192, 144, make_zoom(model->bounds(), glm::vec3(0.3f, -0.2f, 1.0f), r, 0.95f * r, g)});

  std::vector<pb::Stats> stats(runs.size());
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < runs.size(); ++i)
    threads.emplace_back(
        [&, i] { stats[i] = stream_and_check(server.port(), runs[i].name, runs[i].trace, runs[i].w, runs[i].h); });
  for (auto& t : threads) t.join();

  std::uint32_t sub = 0, frames = 0;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    EXPECT_EQ(stats[i].key_frames() + stats[i].sub_frames(), runs[i].trace.size()) << runs[i].name;
    sub += stats[i].sub_frames();
    frames += stats[i].frames_sent();
  }
  EXPECT_GT(sub, 0u) << "the speculation path never served a sub-frame";
  // /metrics agrees with the sessions: every frame was timed in each stage histogram.
  std::string metrics;
  ASSERT_EQ(http_get(server.port(), "/metrics", metrics), 200);
  EXPECT_EQ(metric_value(metrics, "catgs_frames_total"), frames);
  EXPECT_EQ(metric_value(metrics, "catgs_render_frames_total{kind=\"sub\"}"), sub);
  EXPECT_EQ(metric_value(metrics, "catgs_render_seconds_count{kind=\"key\"}") +
                metric_value(metrics, "catgs_render_seconds_count{kind=\"sub\"}"),
            frames);
  for (const char* h : {"catgs_queue_seconds_count", "catgs_convert_seconds_count", "catgs_encode_seconds_count",
                        "catgs_encode_psnr_db_count", "catgs_speculation_window_count"})
    EXPECT_EQ(metric_value(metrics, h), frames) << h;
  EXPECT_NE(metrics.find("catgs_info{renderer=\"cpu\",encoder=\"x264\",pipeline=\"catgs\"} 1"), std::string::npos)
      << metrics;
}

TEST(MultiSession, DifferentTracesAndSizesAllGetCorrectFrames) { three_sessions_get_correct_frames({}); }

// The same through one render lane that keeps two frames in flight (render_scheduler.h "Frames in
// flight", the CUDA core's default): a frame begun for one session, the next session's begun
// before it is finished, and every frame still answers its own pose with its own picture.
TEST(MultiSession, ALaneWithTwoFramesInFlightServesEverySessionCorrectly) {
  three_sessions_get_correct_frames({"--render-lanes", "1", "--frames-per-lane", "2"});
}

// The biker served by a server that may use one core: its affinity mask, inherited from this
// thread's for the fork (usable_cores reads it), which is restored after.
std::unique_ptr<ServerProcess> one_core_server(const std::vector<std::string>& flags) {
  cpu_set_t mine, one;
  if (sched_getaffinity(0, sizeof(mine), &mine) != 0) throw std::runtime_error("sched_getaffinity failed");
  CPU_ZERO(&one);
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &mine)) {
      CPU_SET(c, &one);
      break;
    }
  if (sched_setaffinity(0, sizeof(one), &one) != 0) throw std::runtime_error("sched_setaffinity failed");
  std::unique_ptr<ServerProcess> server;
  try {
    server = std::make_unique<ServerProcess>(server_args(kBiker, flags));
  } catch (...) {
    sched_setaffinity(0, sizeof(mine), &mine);
    throw;
  }
  sched_setaffinity(0, sizeof(mine), &mine);
  return server;
}

// The preset ladder never lowers the picture silently (issue 91): a server that may use one core
// (its affinity mask, inherited from this thread) gives a lone 800x448 session x264 superfast;
// a second session halves the encoders' share, and the first session's encoder steps down at
// once. Its Stats say the new preset and the picture it gives, /metrics counts the step, the
// log names it.
TEST(MultiSession, APresetStepDownIsSaidInStatsMetricsAndTheLog) {
  const auto server = one_core_server({"--pipeline", "exact"});
  const auto model = load_model(kBiker);
  const server::CameraPose view = server::first_view_pose(server::frame_from_content(*model), 800, 448);
  std::uint32_t sequence = 0;
  // Poses until a Stats comes that satisfies `done` (a frame's worth of poses between reads).
  const auto stats_until = [&](StreamClient& c, const std::function<bool(const pb::Stats&)>& done) {
    for (int tries = 0; tries < 40; ++tries) {
      pb::Pose pose =
          pose_from_camera(Camera::from_pose(view.position + glm::vec3(0.01f * static_cast<float>(sequence), 0, 0),
                                             view.orientation, view.vertical_fov_deg, 800, 448),
                           sequence, now_ms());
      sequence++;
      c.send_pose(pose);
      auto m = wait_for(c, 1500, [](const pb::ServerMessage& x) { return x.has_stats(); });
      if (m && m->stats().frames_sent() > 0 && done(m->stats())) return m->stats();
    }
    ADD_FAILURE() << "no such Stats";
    return pb::Stats{};
  };
  StreamClient first;
  first.connect(server->port());
  first.hello(800, 448);
  const pb::Stats alone = stats_until(first, [](const pb::Stats& s) { return s.encode_psnr_db_mean() > 0; });
  EXPECT_EQ(alone.encoder(), "x264 superfast");
  StreamClient second;
  second.connect(server->port());
  second.hello(800, 448);
  const pb::Stats shared = stats_until(first, [](const pb::Stats& s) { return s.encoder() != "x264 superfast"; });
  EXPECT_EQ(shared.encoder().rfind("x264 ultrafast", 0), 0u) << shared.encoder();
  EXPECT_GT(shared.encode_psnr_db_mean(), 25.0);
  std::cout << "[ info ] one session: " << alone.encoder() << " " << alone.encode_psnr_db_mean()
            << " dB; two: " << shared.encoder() << " " << shared.encode_psnr_db_mean() << " dB\n";
  std::string metrics;
  ASSERT_EQ(http_get(server->port(), "/metrics", metrics), 200);
  EXPECT_GE(metric_value(metrics, "catgs_encoder_steps_down_total"), 1) << metrics;
  EXPECT_NE(server->log().find("encoder: x264 superfast -> x264 ultrafast"), std::string::npos) << server->log();
}

// --x264-floor: the same one-core server keeps its lone session at superfast, and the door
// refuses the second visitor, whose stream would step both below it, with the reason.
TEST(MultiSession, TheX264FloorRefusesAVisitorTheCoresCannotEncodeAtIt) {
  const auto server = one_core_server({"--x264-floor", "superfast"});
  StreamClient first;
  first.connect(server->port());
  first.hello(800, 448);
  StreamClient second;
  second.connect(server->port());
  try {
    second.hello(800, 448);
    ADD_FAILURE() << "the second visitor was let in";
  } catch (const loadgen::Refused& r) {
    EXPECT_EQ(r.error().code(), pb::ERROR_SERVER_FULL);
    EXPECT_NE(r.error().reason().find("cannot encode another 800x448 stream at x264 superfast"), std::string::npos)
        << r.error().reason();
    EXPECT_GT(r.error().retry_after_ms(), 0u);
  }
  std::string metrics;
  ASSERT_EQ(http_get(server->port(), "/metrics", metrics), 200);
  EXPECT_EQ(metric_value(metrics, "catgs_core_refusals_total"), 1) << metrics;
  EXPECT_EQ(metric_value(metrics, "catgs_sessions"), 1) << metrics;
}

// 200 connect / Hello / pose / disconnect cycles (clean closes and abrupt drops, before and
// after the frame arrived): afterwards no session is left and the server's memory has stopped
// growing. What the server's allocator holds (catgs_heap_in_use_bytes) is read after the warm-up
// and after each quarter of the cycles, once every close was noticed: a leak grows it quarter by
// quarter. RSS is reported beside it, not judged: malloc's arenas and thread caches move it in
// steps, up or down, in any one quarter (+18 MiB in one half and +2 in the other in one run, -18
// in another). The server runs with two malloc arenas (MALLOC_ARENA_MAX, inherited).
TEST(MultiSession, DisconnectsMidStreamFreeEverything) {
  setenv("MALLOC_ARENA_MAX", "2", 1);
  // 240 sessions from one address as fast as they go: on an idle machine that is over 40 a
  // second, past the default Hello limit (20/s, burst 100), which is not what this test is about.
  ServerProcess server(server_args(kBiker, {"--rate-limits", "hello=200/400"}));
  unsetenv("MALLOC_ARENA_MAX");
  const Trace orbit = biker_orbit(96, 64, 8);
  auto cycle = [&](int i) { connect_and_leave(server.port(), i, orbit); };
  auto settle = [&] {  // until the server has noticed every close
    std::string metrics;
    const auto deadline = Clock::now() + std::chrono::seconds(10);
    do {
      http_get(server.port(), "/metrics", metrics);
      if (metric_value(metrics, "catgs_sessions") == 0 && metric_value(metrics, "catgs_connections") == 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    } while (Clock::now() < deadline);
    return metrics;
  };
  for (int i = 0; i < 40; ++i) cycle(i);  // warm-up: allocator pools, thread stacks, caches
  std::vector<double> heap{metric_value(settle(), "catgs_heap_in_use_bytes")};
  std::vector<long> rss{rss_kib(server.pid())};
  ASSERT_GT(heap[0], 0) << "no catgs_heap_in_use_bytes in /metrics";
  const auto t0 = Clock::now();
  std::string metrics;
  for (int quarter = 0; quarter < 4; ++quarter) {
    for (int i = 0; i < 50; ++i) cycle(40 + 50 * quarter + i);
    metrics = settle();
    heap.push_back(metric_value(metrics, "catgs_heap_in_use_bytes"));
    rss.push_back(rss_kib(server.pid()));
  }
  std::cout << "[ info ] 200 cycles in " << std::chrono::duration<double>(Clock::now() - t0).count()
            << " s; server RSS after the warm-up and each 50 cycles (MiB):";
  for (long r : rss) std::cout << " " << r / 1024;
  std::cout << "; heap in use:";
  for (double h : heap) std::cout << " " << h / (1 << 20);
  std::cout << "\n";
  EXPECT_EQ(metric_value(metrics, "catgs_sessions"), 0) << metrics;
  EXPECT_EQ(metric_value(metrics, "catgs_connections"), 0) << metrics;
  EXPECT_EQ(metric_value(metrics, "catgs_sessions_total"), 240) << metrics;
  EXPECT_EQ(metric_value(metrics, "catgs_session_errors_total"), 0) << metrics;
  // A leaked session would keep its renderer buffers and x264 encoder (MiBs each): 200 of them
  // would pass this bound many times over (it allows about 20 KiB a cycle).
  EXPECT_LT(heap.back() - heap.front(), 4 * 1024 * 1024)
      << "the server's heap in use grew from " << heap.front() / (1 << 20) << " MiB after the warm-up to "
      << heap.back() / (1 << 20) << " MiB after 200 more cycles: a leak";
  std::string body;
  EXPECT_EQ(http_get(server.port(), "/healthz", body), 200);
}

// --encoder nvenc fails at start-up with the reason where there is no NVENC; --encoder auto then
// falls back to x264, logs why and counts it.
TEST(MultiSession, EncoderFlagsNvencAndAutoFallback) {
  try {
    ServerProcess nvenc(server_args(kBiker, {"--encoder", "nvenc"}));
    std::cout << "[ info ] NVENC opened here: the fallback path is not exercised\n";
    return;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("catgs-server: nvenc: "), std::string::npos) << e.what();
  }
  ServerProcess server(server_args(kBiker, {"--encoder", "auto"}));
  EXPECT_NE(server.log().find("encoder: x264 (auto: x264 (nvenc: "), std::string::npos) << server.log();
  StreamClient c;
  c.connect(server.port());
  EXPECT_EQ(c.hello(64, 64).encoder(), "x264");
  c.send_pose(pose_from_camera(biker_orbit(64, 64, 2)[0].camera, 0, now_ms()));
  ASSERT_TRUE(wait_for(c, 10000, [](const pb::ServerMessage& s) { return s.has_frame(); }));
  std::string metrics;
  http_get(server.port(), "/metrics", metrics);
  // The start-up probe and the session's encoder.
  EXPECT_EQ(metric_value(metrics, "catgs_encoder_fallbacks_total"), 2) << metrics;
}

// catgs-loadgen end to end: two sessions with different traces and sizes, decoding, then a
// two-step ramp; the JSON report holds what the table shows.
TEST(MultiSession, LoadgenReportsAndRamps) {
  ServerProcess server(server_args(kBiker, {"--pipeline", "catgs"}));
  const std::string json_path = "/tmp/catgs-itest-loadgen-" + std::to_string(server.port()) + ".json";
  const std::string base = std::string(CATGS_LOADGEN_BIN) + " --port " + std::to_string(server.port()) + " --scene " +
                           kBiker + " --size 160x120,128x96 --rate 20 --decode 1 --warmup 1 --json " + json_path;
  // The second session replays a real camera path when the data is there.
  const std::string cams = kDataDir + "/traces/flowers_sh3.cameras.json";
  const std::string second = std::filesystem::exists(cams) ? "cameras:" + cams : "orbit";
  ASSERT_EQ(std::system((base + " --sessions 2 --seconds 3 --trace orbit," + second + " > /dev/null").c_str()), 0);
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json_path));
  ASSERT_EQ(j["run"]["sessions"].size(), 2u);
  for (const auto& s : j["run"]["sessions"]) {
    EXPECT_GT(s["frames"].get<int>(), 0) << s.dump();
    EXPECT_EQ(s["decoded"].get<int>(), s["frames"].get<int>()) << s.dump();
    EXPECT_EQ(s["errors"].get<int>(), 0) << s.dump();
    EXPECT_GT(s["latency"]["p50_ms"].get<double>(), 0.0);
    EXPECT_LE(s["latency"]["p50_ms"].get<double>(), s["latency"]["p99_ms"].get<double>());
  }
  EXPECT_EQ(j["run"]["sessions"][1]["width"].get<int>(), 128);
  // Issue 92: a trace is made once a run (two sessions, two traces: two), and the run records the
  // client's own CPU time.
  EXPECT_EQ(j["traces_made"].get<int>(), 2) << j.dump();
  EXPECT_GT(j["run"]["client_cpu"]["cpu_s"].get<double>(), 0.0);
  EXPECT_GE(j["run"]["client_cpu"]["wall_s"].get<double>(), 3.0);
  // Each pose carries the latency of the newest frame before it (Pose.shown_latency_ms); the
  // server's end-to-end histogram must agree with what the client measured (the same samples but
  // for the warm-up and the last frame of each session).
  std::string metrics;
  http_get(server.port(), "/metrics", metrics);
  const double e2e_count = metric_value(metrics, "catgs_pose_to_frame_seconds_count");
  const double e2e_mean_ms = 1000.0 * metric_value(metrics, "catgs_pose_to_frame_seconds_sum") / e2e_count;
  const double client_mean_ms = j["run"]["total"]["latency"]["mean_ms"].get<double>();
  const double client_frames = j["run"]["total"]["frames"].get<double>();
  std::cout << "[ info ] end to end: /metrics " << e2e_count << " samples, mean " << e2e_mean_ms
            << " ms; catgs-loadgen " << client_frames << " frames, mean " << client_mean_ms << " ms\n";
  EXPECT_GE(e2e_count, 0.5 * client_frames);
  EXPECT_LE(e2e_count, client_frames);
  EXPECT_NEAR(e2e_mean_ms, client_mean_ms, 0.35 * client_mean_ms + 2.0);
  // Per-session frame rate: the server's per-interval rates average what the client counted
  // (whatever the CPU manages of the 20 poses a second asked for).
  const double fps_count = metric_value(metrics, "catgs_session_fps_count");
  const double fps_mean = metric_value(metrics, "catgs_session_fps_sum") / fps_count;
  const double client_fps = j["run"]["total"]["fps_total"].get<double>() / 2.0;
  std::cout << "[ info ] per-session FPS: /metrics " << fps_count << " intervals, mean " << fps_mean
            << "; catgs-loadgen mean " << client_fps << "\n";
  EXPECT_GE(fps_count, 2);
  EXPECT_NEAR(fps_mean, client_fps, 0.3 * client_fps);
  EXPECT_EQ(j["run"]["sessions"][1]["trace"].get<std::string>(), second);
  // The pose's wait before its render, and the part of it its job waited for a lane
  // (FrameTimings.lane_wait_ms): a part, so at least 0 and at most the whole.
  const nlohmann::json& srv = j["run"]["total"]["server"];
  EXPECT_GE(srv["lane_wait_ms"].get<double>(), 0.0);
  EXPECT_LE(srv["lane_wait_ms"].get<double>(), srv["queue_ms"].get<double>()) << srv.dump();
  ASSERT_EQ(std::system((base + " --sessions 2 --seconds 1.5 --ramp --trace orbit > /dev/null").c_str()), 0);
  const nlohmann::json ramp = nlohmann::json::parse(std::ifstream(json_path));
  ASSERT_EQ(ramp["ramp"].size(), 2u) << ramp.dump();  // 1 then 2 sessions, no bound to break
  EXPECT_EQ(ramp["largest_sessions_held"].get<int>(), 2);
  EXPECT_EQ(ramp["ramp"][1]["total"]["sessions"].get<int>(), 2);
  // Three sessions over the two steps, at two sizes: each orbit made once, not once a session.
  EXPECT_EQ(ramp["traces_made"].get<int>(), 2) << ramp.dump();
  EXPECT_TRUE(ramp["ramp"][1].contains("client_cpu"));
  std::filesystem::remove(json_path);
}

// catgs-loadgen --scene-name (issue 20): against a server with two scenes, the session asks for
// the second by name and its decoded frames match a CPU render of that scene (--check-every); the
// same run without the name gets the server's first scene, and the check against the second one
// fails (exit status 1), so the name is what picked it.
TEST(MultiSession, LoadgenAsksForASceneByName) {
  const std::string flowers = kDataDir + "/scenes/flowers_sh3.ply";
  const std::string cams = kDataDir + "/traces/flowers_sh3.cameras.json";
  if (!std::filesystem::exists(flowers) || !std::filesystem::exists(cams))
    GTEST_SKIP() << "real data not found under " << kDataDir << " (flowers_sh3.ply / flowers_sh3.cameras.json)";
  // Frames drawn at the poses sent (--pose-prediction off): on a busy clean-clone run its reference
  // renders held the client's latency at 230 ms, so prediction led by its 200 ms ceiling along the
  // training views' path, and one checked frame of 16 fell to 29.8 dB (mean 32.8; whether the long
  // lead made the stream harder was not measured). This test is about the scene's name.
  ServerProcess server(
      server_args(kBiker, {"--scene", flowers, "--crf", "18", "--bitrate", "off", "--pose-prediction", "off"}));
  const std::string json_path = "/tmp/catgs-itest-scene-name-" + std::to_string(server.port()) + ".json";
  const std::string base = std::string(CATGS_LOADGEN_BIN) + " --port " + std::to_string(server.port()) + " --scene " +
                           flowers + " --trace cameras:" + cams +
                           " --size 480x320 --rate 10 --seconds 2 --warmup 0 --check-every 2 --json " + json_path;
  const int named = std::system((base + " --scene-name flowers_sh3 > /dev/null").c_str());
  ASSERT_TRUE(std::filesystem::exists(json_path)) << "catgs-loadgen wrote no report (status " << named << ")";
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json_path));
  const auto& s = j["run"]["sessions"][0];
  ASSERT_EQ(named, 0) << s.dump();  // the session's frames, checks and PSNR say which part failed
  EXPECT_EQ(s["scene"].get<std::string>(), "flowers_sh3") << s.dump();
  EXPECT_GT(s["checked"].get<int>(), 0) << s.dump();
  EXPECT_GE(s["psnr_min_db"].get<double>(), 30.0) << s.dump();
  const std::string err_path = json_path + ".stderr";
  const int status = std::system((base + " > /dev/null 2> " + err_path).c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1) << "biker's frames passed a check against flowers_sh3";
  // The failure names its kind: frames were checked and one was low (not "no frame checked").
  std::stringstream err;
  err << std::ifstream(err_path).rdbuf();
  EXPECT_NE(err.str().find("1 failed the reference check (a frame below 30 dB"), std::string::npos) << err.str();
  std::filesystem::remove(err_path);
  const nlohmann::json first = nlohmann::json::parse(std::ifstream(json_path));
  EXPECT_EQ(first["run"]["sessions"][0]["scene"].get<std::string>(), "biker");
  std::filesystem::remove(json_path);
}

// The reference check draws each frame's reference at the LOD bound the server drew it at (issue
// 72): the biker served with its level of detail at 4 px (0.67 px at 160x120, where its frames
// are about 30 dB from full detail, nearer the supersampled render than full detail is) passes a
// 35 dB bar, which a full-detail reference would fail; the frames say they were drawn from the cut.
TEST(MultiSession, LoadgenChecksFramesAtTheirLodBound) {
  // A cache folder of its own: the biker's LOD file written there would be served to every later
  // test's server (a LOD file is used whatever --lod-min-gaussians says), whose checks expect full
  // detail. The later --cache-dir wins.
  const std::filesystem::path cache = std::filesystem::temp_directory_path() / "catgs-itest-cache-lod-check";
  std::filesystem::remove_all(cache);
  // Frames at the poses sent, as in LoadgenAsksForASceneByName: this test is about the bound.
  ServerProcess server(server_args(kBiker, {"--lod-min-gaussians", "0", "--lod-error", "4", "--crf", "18", "--bitrate",
                                            "off", "--cache-dir", cache.string(), "--pose-prediction", "off"}));
  const std::string json_path = "/tmp/catgs-itest-lod-check-" + std::to_string(server.port()) + ".json";
  const std::string cmd = std::string(CATGS_LOADGEN_BIN) + " --port " + std::to_string(server.port()) + " --scene " +
                          kBiker + " --size 160x120 --rate 10 --seconds 2 --warmup 0 --check-every 2" +
                          " --check-min-psnr 35 --json " + json_path + " > /dev/null";
  EXPECT_EQ(std::system(cmd.c_str()), 0);
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json_path));
  const auto& s = j["run"]["sessions"][0];
  EXPECT_GT(s["checked"].get<int>(), 0) << s.dump();
  EXPECT_GE(s["psnr_min_db"].get<double>(), 35.0) << s.dump();
  EXPECT_NEAR(s["server"]["lod_error_px_max"].get<double>(), 4.0 * 120 / 720, 0.01) << s.dump();
  std::filesystem::remove(json_path);
  std::filesystem::remove_all(cache);
}

// catgs-loadgen against a full server: one session streams, the other is refused. The refused
// one is reported as refused (status, refusal, no numbers), the run exits 3 (refused, nothing
// failed), no PSNR is claimed for unchecked frames, and the progress line shows on stderr while
// it runs. Poses sent faster than the CPU renders are skipped (latest pose wins), not dropped.
TEST(MultiSession, LoadgenReportsRefusedSessionsSkipsAndProgress) {
  ServerProcess server(server_args(kBiker, {"--max-sessions", "1", "--threads", "2"}));
  const std::string stem = "/tmp/catgs-itest-refused-" + std::to_string(server.port());
  const std::string cmd = std::string(CATGS_LOADGEN_BIN) + " --port " + std::to_string(server.port()) +
                          " --sessions 2 --offset-s 0 --size 320x240 --rate 400 --seconds 3 --progress 0.5 --json " +
                          stem + ".json > " + stem + ".out 2> " + stem + ".err";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3) << "refused sessions must not exit 0";
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(stem + ".json"));
  std::stringstream out, err;
  out << std::ifstream(stem + ".out").rdbuf();
  err << std::ifstream(stem + ".err").rdbuf();
  int ok = 0, refused = 0;
  for (const auto& s : j["run"]["sessions"]) {
    if (s["status"] == "refused") {
      refused++;
      EXPECT_NE(s["refusal"].get<std::string>().find("ERROR_SERVER_FULL"), std::string::npos) << s.dump();
      EXPECT_EQ(s["frames"].get<int>(), 0);
      continue;
    }
    ok++;
    EXPECT_EQ(s["status"], "ok") << s.dump();
    EXPECT_GT(s["frames"].get<int>(), 10) << s.dump();
    EXPECT_TRUE(s["psnr_mean_db"].is_null()) << "nothing was checked: " << s.dump();
    // 400 poses a second against a CPU render of tens of ms: most poses are replaced by newer
    // ones; the newest is always rendered, so none is lost.
    const int sent = s["poses_sent"].get<int>(), frames = s["frames"].get<int>();
    const int skipped = s["skipped"].get<int>(), dropped = s["dropped"].get<int>();
    EXPECT_GT(skipped, frames) << s.dump();
    EXPECT_EQ(dropped, 0) << s.dump();
    // Each frame answers a different pose (in order, none twice): every pose is accounted for once.
    EXPECT_EQ(skipped + dropped + frames, sent) << s.dump();
    EXPECT_GT(s["server_skipped"].get<int>(), 0) << s.dump();
  }
  EXPECT_EQ(ok, 1);
  EXPECT_EQ(refused, 1);
  EXPECT_EQ(j["run"]["total"]["refused"].get<int>(), 1);
  // The server's counters agree: skips are not drops. A drop is a pose pending, or a frame in
  // flight, when its session ends: at most 2 for the one session that streamed.
  std::string metrics;
  ASSERT_EQ(http_get(server.port(), "/metrics", metrics), 200);
  EXPECT_GT(metric_value(metrics, "catgs_poses_skipped_total"), 100.0) << metrics;
  EXPECT_LE(metric_value(metrics, "catgs_dropped_frames_total"), 2.0) << metrics;
  EXPECT_NE(out.str().find("refused by the server: ERROR_SERVER_FULL"), std::string::npos) << out.str();
  EXPECT_EQ(out.str().find("0x0"), std::string::npos) << out.str();
  EXPECT_NE(err.str().find("sessions: 1 open, 1 refused, 0 failed"), std::string::npos) << err.str();
  for (const char* ext : {".json", ".out", ".err"}) std::filesystem::remove(stem + ext);
}

// The GPU script's correctness run, on the CPU: catgs-loadgen decodes the frames of 3 sessions and
// compares every 3rd with the CPU reference render of its pose (exit 0 only if all >= 30 dB and
// every session checked some); an impossible bar must fail the run. One render lane serves the
// three closed-loop sessions first come first served, so none falls far behind the others.
// CRF 18, not the default 23: the test is about the check and the lanes (here: least PSNR
// 35.9-38.2 dB at 23, 38.9-41.2 at 18). A loaded CI machine checked frames at 28.6, 29.3 (CRF 23)
// and 28.4 dB (CRF 18): catgs sub-frames of a closed loop at 1.6-6 poses/s, whose windows then
// spanned seconds of the orbit (23-34 dB against the exact render, every checked frame; the key
// frames 38 dB and more). The planner now counts a pose clock under 30 Hz as 30 Hz
// (SpeculationPlanner::kLongestPoseInterval_s), so such poses are key frames.
TEST(MultiSession, LoadgenReferenceCheckAndFairRenderLanes) {
  ServerProcess server(
      server_args(kBiker, {"--pipeline", "catgs", "--render-lanes", "1", "--threads", "3", "--crf", "18"}));
  const std::string json_path = "/tmp/catgs-itest-check-" + std::to_string(server.port()) + ".json";
  const std::string base = std::string(CATGS_LOADGEN_BIN) + " --port " + std::to_string(server.port()) + " --scene " +
                           kBiker + " --size 160x120,128x96,96x96 --rate 0 --sessions 3" +
                           " --warmup 1 --check-every 3 --json " + json_path;
  // 8 s: on a loaded 2-core machine (ctest -j 2 beside a build) 3 s gave one session too few
  // frames to check one, and once 5 s did (CI: 18 frames in 5 s for the three). The exit status
  // is checked after the sessions' own checks, which say which session and why.
  const int status = std::system((base + " --seconds 8 > /dev/null").c_str());
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json_path));
  ASSERT_EQ(j["run"]["sessions"].size(), 3u);
  int most = 0, fewest = 1 << 30;
  for (const auto& s : j["run"]["sessions"]) {
    EXPECT_GT(s["checked"].get<int>(), 0) << s.dump();
    EXPECT_EQ(s["check_failures"].get<int>(), 0) << s.dump();
    EXPECT_GE(s["psnr_min_db"].get<double>(), 30.0) << s.dump();
    most = std::max(most, s["frames"].get<int>());
    fewest = std::min(fewest, s["frames"].get<int>());
  }
  std::cout << "[ info ] frames per session over 8 s with one render lane: " << fewest << " to " << most << "\n";
  EXPECT_GE(2 * fewest, most) << "a session fell behind the others";
  EXPECT_EQ(status, 0) << "catgs-loadgen's reference check failed";
  EXPECT_NE(std::system((base + " --seconds 1 --check-min-psnr 200 > /dev/null").c_str()), 0)
      << "a reference check nothing can pass must fail the run";
  std::filesystem::remove(json_path);
}

}  // namespace
