// Scenes on demand (issue 20, "Scene choice"; server/process/scene_store.h), against the real
// server on the CPU renderer: scenes past the first load on first use, once for all the sessions
// that ask, with LoadProgress before Welcome; a bad file or a load that hangs ends only its own
// sessions; a memory
// budget unloads unused scenes and keeps those in use; /metrics counts it all. The scenes are
// copies of the bundled biker under other names (always present), so nothing here skips.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "loadgen/stream_client.h"
#include "scene/scene_cache.h"
#include "server_process.h"
#include "stream_checks.h"

namespace {

using namespace catgs;
using namespace catgs::loadgen;
using namespace catgs::itest;
namespace fs = std::filesystem;

// A fresh folder with copies of the biker named `names` (NAME.compressed.ply); returns their paths.
std::vector<std::string> biker_copies(const std::string& test, const std::vector<std::string>& names) {
  const fs::path dir = fs::temp_directory_path() / ("catgs-itest-" + test + "-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::vector<std::string> out;
  for (const std::string& n : names) {
    out.push_back((dir / (n + ".compressed.ply")).string());
    fs::copy_file(kBiker, out.back());
  }
  return out;
}

double metric(int port, const std::string& series) {
  std::string body;
  if (http_get(port, "/metrics", body) != 200) return -2;
  return metric_value(body, series);
}

// Polls /metrics until `series` equals `want` (sessions end asynchronously after a close).
bool metric_becomes(int port, const std::string& series, double want, int timeout_ms = 10000) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    if (metric(port, series) == want) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// Frames for a few poses of the biker orbit (the session still streams).
void expect_frames(StreamClient& c, std::uint32_t first_sequence, int count, const char* what) {
  const Trace orbit = biker_orbit(160, 120, count);
  for (int i = 0; i < count; ++i) {
    c.send_pose(pose_from_camera(orbit[static_cast<std::size_t>(i)].camera, first_sequence + i, now_ms()));
    EXPECT_TRUE(wait_for(c, 20000, [](const pb::ServerMessage& s) { return s.has_frame(); }))
        << what << ": no frame for pose " << i;
  }
}

// Two sessions ask at once for a scene that is not loaded: one load, LoadProgress before each
// Welcome, rising to 100; a client that did not ask for progress gets Welcome first, as before.
TEST(SceneLoading, TwoSessionsShareOneLoadAndSeeProgressBeforeWelcome) {
  const auto files = biker_copies("shared", {"first", "second", "third"});
  ServerProcess server(server_args(files[0], {"--scene", files[1], "--scene", files[2]}));
  std::string body;
  ASSERT_EQ(http_get(server.port(), "/scenes", body), 200);
  const nlohmann::json scenes = nlohmann::json::parse(body);
  ASSERT_EQ(scenes.size(), 3u) << body;
  EXPECT_EQ(scenes[0]["loaded"], true);
  EXPECT_FALSE(scenes[0]["bounds"].is_null()) << body;
  EXPECT_EQ(scenes[1]["loaded"], false);
  EXPECT_EQ(scenes[1]["gaussians"], 152746) << "listed from the header: " << body;
  EXPECT_EQ(scenes[1]["format"], "compressed_ply");
  EXPECT_TRUE(scenes[1]["bounds"].is_null()) << body;
  EXPECT_EQ(metric(server.port(), "catgs_scenes_loaded"), 1);
  EXPECT_EQ(metric(server.port(), "catgs_scene_loads_total"), 1);

  std::vector<pb::ServerMessage> before[2];
  pb::Welcome welcome[2];
  std::string failure[2];
  StreamClient clients[2];
  std::vector<std::thread> threads;
  for (int k = 0; k < 2; ++k) {
    clients[k].connect(server.port());
    threads.emplace_back([&, k] {
      try {
        welcome[k] = clients[k].hello(160, 120, "", 30000, "second", &before[k], /*load_progress=*/true);
      } catch (const std::exception& e) {
        failure[k] = e.what();
      }
    });
  }
  for (auto& t : threads) t.join();
  for (int k = 0; k < 2; ++k) {
    ASSERT_EQ(failure[k], "") << "session " << k;
    EXPECT_EQ(welcome[k].scene_name(), "second");
    ASSERT_FALSE(before[k].empty()) << "session " << k << ": no LoadProgress before Welcome";
    int last = -1;
    for (const pb::ServerMessage& m : before[k]) {
      ASSERT_TRUE(m.has_load_progress()) << "session " << k << ": " << m.ShortDebugString();
      EXPECT_EQ(m.load_progress().scene_name(), "second");
      EXPECT_GT(static_cast<int>(m.load_progress().percent()), last) << "session " << k << ": progress must rise";
      last = static_cast<int>(m.load_progress().percent());
    }
    EXPECT_EQ(last, 100) << "session " << k << ": the last LoadProgress before Welcome says 100";
    std::cout << "[ info ] session " << k << ": " << before[k].size() << " LoadProgress messages before Welcome\n";
  }
  EXPECT_EQ(metric(server.port(), "catgs_scene_loads_total"), 2) << "one load for the two sessions";
  EXPECT_EQ(metric(server.port(), "catgs_scenes_loaded"), 2);
  for (int k = 0; k < 2; ++k) expect_frames(clients[k], 0, 2, "a session of the loaded scene");

  // Without Hello.load_progress: Welcome is the first message, as from servers before it.
  StreamClient old;
  old.connect(server.port());
  std::vector<pb::ServerMessage> old_before;
  EXPECT_EQ(old.hello(160, 120, "", 30000, "third", &old_before).scene_name(), "third");
  EXPECT_TRUE(old_before.empty()) << old_before.front().ShortDebugString();
  EXPECT_EQ(metric(server.port(), "catgs_scene_loads_total"), 3);
  ASSERT_EQ(http_get(server.port(), "/scenes", body), 200);
  EXPECT_FALSE(nlohmann::json::parse(body)[1]["bounds"].is_null()) << "bounds known once loaded: " << body;
}

// A scene file that is broken past its header: the session that asks for it gets an Error naming
// the file; a session streaming another scene meanwhile goes on; the failure is counted.
TEST(SceneLoading, BadSceneFileEndsOnlyItsOwnSession) {
  auto files = biker_copies("bad", {"good"});
  const std::string bad = fs::path(files[0]).parent_path().string() + "/broken.ply";
  {
    std::ofstream f(bad, std::ios::binary);
    f << "ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n"
      << std::string(100, '\0');
  }
  ServerProcess server(server_args(files[0], {"--scene", bad}));
  StreamClient good;
  good.connect(server.port());
  good.hello(160, 120);
  expect_frames(good, 0, 2, "the good session before");
  StreamClient broken;
  broken.connect(server.port());
  try {
    broken.hello(160, 120, "", 30000, "broken", nullptr, true);
    ADD_FAILURE() << "a session on a broken scene file was welcomed";
  } catch (const Refused& r) {
    EXPECT_EQ(r.error().code(), pb::ERROR_INTERNAL);
    EXPECT_NE(r.error().reason().find(bad), std::string::npos) << "the file is named: " << r.error().reason();
    EXPECT_NE(r.error().reason().find("broken"), std::string::npos) << r.error().reason();
  }
  EXPECT_TRUE(expect_closed(broken));
  expect_frames(good, 2, 3, "the good session after the other's failed load");
  EXPECT_EQ(metric(server.port(), "catgs_scene_load_failures_total"), 1);
  EXPECT_EQ(metric(server.port(), "catgs_scenes_loaded"), 1);
}

// A load that hangs (the file became a FIFO nobody writes: open() blocks, as on a stalled network
// file system) ends its waiting session after --scene-load-timeout-ms with ERROR_TIMEOUT naming
// the scene, counted; the other session streams on. Writing to the FIFO at the end lets the load
// fail (an empty file), so the server stops cleanly.
TEST(SceneLoading, HungLoadTimesOutItsSessionOnly) {
  const auto files = biker_copies("hung", {"good", "stuck"});
  ServerProcess server(server_args(files[0], {"--scene", files[1], "--scene-load-timeout-ms", "1500"}));
  const int port = server.port();
  fs::remove(files[1]);  // listed from its header at start-up; from now on a FIFO
  ASSERT_EQ(mkfifo(files[1].c_str(), 0600), 0);
  StreamClient good;
  good.connect(port);
  good.hello(160, 120);
  expect_frames(good, 0, 2, "the good session before");
  StreamClient stuck;
  stuck.connect(port);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    stuck.hello(160, 120, "", 30000, "stuck", nullptr, true);
    ADD_FAILURE() << "a session on a scene whose load hangs was welcomed";
  } catch (const Refused& r) {
    EXPECT_EQ(r.error().code(), pb::ERROR_TIMEOUT);
    EXPECT_NE(r.error().reason().find("scene 'stuck' did not load within 1500 ms"), std::string::npos)
        << r.error().reason();
  }
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GE(waited, 1.4);
  EXPECT_LT(waited, 10.0);
  EXPECT_TRUE(expect_closed(stuck));
  expect_frames(good, 2, 3, "the good session after the other's timeout");
  EXPECT_EQ(metric(port, "catgs_timeouts_total{kind=\"scene_load\"}"), 1);
  EXPECT_EQ(metric(port, "catgs_scene_load_failures_total"), 0) << "the load is still under way";
  // Unblock the load: whenever a reader waits in open() (format detection opens the file, then
  // the reader opens it again), a writer opens and closes the FIFO: the reader sees an empty file.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (metric(port, "catgs_scene_load_failures_total") != 1 && std::chrono::steady_clock::now() < deadline) {
    const int fd = open(files[1].c_str(), O_WRONLY | O_NONBLOCK);  // ENXIO while no reader waits
    if (fd >= 0) close(fd);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(metric(port, "catgs_scene_load_failures_total"), 1);
}

// --scene-memory-mb that holds one biker (8.2 MiB) but not two: a scene in use is kept when
// another loads (both loaded, over the budget), and unloaded when its last session leaves;
// switching back loads it again.
TEST(SceneLoading, BudgetUnloadsUnusedScenesAndKeepsUsedOnes) {
  const auto files = biker_copies("budget", {"alpha", "beta"});
  ServerProcess server(server_args(files[0], {"--scene", files[1], "--scene-memory-mb", "12"}));
  const int port = server.port();
  EXPECT_EQ(metric(port, "catgs_scenes_loaded"), 1);
  auto a = std::make_unique<StreamClient>();
  a->connect(port);
  a->hello(160, 120, "", 30000, "alpha");
  StreamClient b;
  b.connect(port);
  b.hello(160, 120, "", 30000, "beta");
  EXPECT_EQ(metric(port, "catgs_scenes_loaded"), 2) << "alpha is in use: kept although over the budget";
  EXPECT_EQ(metric(port, "catgs_scene_unloads_total"), 0);
  expect_frames(*a, 0, 2, "alpha's session while beta loaded");
  a.reset();  // alpha's last session leaves: over the budget, it goes
  EXPECT_TRUE(metric_becomes(port, "catgs_scene_unloads_total", 1)) << server.log();
  EXPECT_EQ(metric(port, "catgs_scenes_loaded"), 1);
  expect_frames(b, 0, 2, "beta's session after alpha's unload");
  std::string body;
  ASSERT_EQ(http_get(port, "/scenes", body), 200);
  const nlohmann::json scenes = nlohmann::json::parse(body);
  EXPECT_EQ(scenes[0]["loaded"], false) << body;
  EXPECT_FALSE(scenes[0]["bounds"].is_null()) << "bounds stay listed after an unload: " << body;
  EXPECT_EQ(scenes[1]["loaded"], true) << body;
  // Back to alpha: loaded again (beta, in use, stays).
  StreamClient again;
  again.connect(port);
  again.hello(160, 120, "", 30000, "alpha");
  EXPECT_EQ(metric(port, "catgs_scene_loads_total"), 3);
  EXPECT_EQ(metric(port, "catgs_scenes_loaded"), 2);
  EXPECT_GT(metric(port, "catgs_scene_bytes"), 12.0 * (1 << 20));
  expect_frames(again, 0, 2, "alpha again");
  EXPECT_NE(server.log().find("scene: unloaded alpha"), std::string::npos) << server.log();
}

}  // namespace

// --scene-cache (issue 37; --lod off: a LOD file, on by default, would be served before the cache):
// `write` reads the scene and writes its cache to the cache folder (--cache-dir, named by the
// scene's content: issue 61), not beside the scene; the next server uses the cache (`read`, the
// default) and streams the same scene; a cache damaged between the two is logged with its reason,
// the scene read, the server serving as before.
TEST(SceneLoading, SceneCacheWrittenThenUsedAndDamageLogged) {
  const auto files = biker_copies("cache", {"cached"});
  const std::string folder = fs::path(files[0]).parent_path().string() + "/derived";
  const std::string cache = derived_file_path(files[0], ".catgs-cache", folder);
  auto args = [&folder](std::vector<std::string> extra) {
    extra.insert(extra.end(), {"--cache-dir", folder});
    return extra;
  };
  {
    ServerProcess server(server_args(files[0], args({"--scene-cache", "write", "--lod", "off"})));
    EXPECT_NE(server.log().find("scene cache: " + cache + ": no cache file; reading the scene"), std::string::npos)
        << server.log();
    EXPECT_NE(server.log().find("scene cache: wrote " + cache), std::string::npos) << server.log();
  }
  ASSERT_TRUE(fs::exists(cache));
  EXPECT_FALSE(fs::exists(files[0] + ".catgs-cache")) << "written beside the user's scene";
  {
    ServerProcess server(server_args(files[0], args({"--lod", "off"})));
    EXPECT_NE(server.log().find("scene cache: " + cache + ": used"), std::string::npos) << server.log();
    StreamClient c;
    c.connect(server.port());
    c.hello(160, 120, "", 30000, "cached");
    expect_frames(c, 0, 2, "a session on the cached scene");
  }
  fs::resize_file(cache, fs::file_size(cache) - 100);
  {
    ServerProcess server(server_args(files[0], args({"--scene-cache", "read", "--lod", "off"})));
    EXPECT_NE(server.log().find("truncated or extended"), std::string::npos) << server.log();
    EXPECT_EQ(server.log().find("scene cache: wrote"), std::string::npos) << "read never writes: " << server.log();
    StreamClient c;
    c.connect(server.port());
    c.hello(160, 120, "", 30000, "cached");
    expect_frames(c, 0, 2, "a session after the damaged cache was passed over");
  }
}
