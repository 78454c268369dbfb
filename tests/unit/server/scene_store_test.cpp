// The scene store (issue 20, "Scene choice"): scenes listed from their headers, loaded on first
// use, one load and one model for every session that asks while it loads, progress that rises to
// 100 before the scene is handed over, a failed load that ends only the waits on it, and unused
// scenes unloaded least recently used first under a memory budget. On copies of the bundled
// biker scene (always present); the loader is load_scene behind a gate the test opens, so
// "while it loads" is not a race.
#include <gtest/gtest.h>

#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>

#include <nlohmann/json.hpp>

#include "scene/ply_io.h"
#include "server_options.h"
#include "process/scene_store.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;
namespace fs = std::filesystem;

// Loads with load_scene once open() is called; counts the loads it was asked for.
struct Gate {
  std::mutex mutex;
  std::condition_variable cv;
  bool open_ = true;
  int loads = 0;
  void close() {
    const std::lock_guard<std::mutex> lock(mutex);
    open_ = false;
  }
  void open() {
    {
      const std::lock_guard<std::mutex> lock(mutex);
      open_ = true;
    }
    cv.notify_all();
  }
  SceneStore::Loader loader() {
    return [this](const std::string& path, const LoadProgress& progress) {
      {
        std::unique_lock<std::mutex> lock(mutex);
        loads++;
        cv.wait(lock, [this] { return open_; });
      }
      return load_scene(path, progress);
    };
  }
};

// What one waiter saw, in order: "p<percent>" for progress, "ready" or "error:<message>".
struct Waiter {
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<std::string> events;
  std::shared_ptr<const LoadedScene> scene;
  bool ended = false;
  SceneStore::Progress progress() {
    return [this](int percent, std::uint64_t, std::uint64_t) {
      const std::lock_guard<std::mutex> lock(mutex);
      events.push_back("p" + std::to_string(percent));
    };
  }
  SceneStore::Ready ready() {
    return [this](std::shared_ptr<const LoadedScene> s, const std::string& error) {
      {
        const std::lock_guard<std::mutex> lock(mutex);
        scene = std::move(s);
        events.push_back(scene ? "ready" : "error:" + error);
        ended = true;
      }
      cv.notify_all();
    };
  }
  bool wait(int ms = 30000) {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(lock, std::chrono::milliseconds(ms), [this] { return ended; });
  }
};

// Copies of the bundled biker under other names (a, b, c, ...), in a fresh folder.
std::vector<SceneStore::Source> biker_copies(const std::vector<std::string>& names) {
  const std::string dir = test::temp_dir();
  std::vector<SceneStore::Source> out;
  for (const std::string& n : names) {
    const std::string path = dir + "/" + n + ".compressed.ply";
    fs::copy_file(test::bundled_scene(), path, fs::copy_options::overwrite_existing);
    out.push_back({path, ""});
  }
  return out;
}

std::uint64_t biker_bytes() { return model_bytes(*test::cached_scene(test::bundled_scene())); }

TEST(SceneStore, ListsScenesFromTheirHeadersWithoutLoading) {
  ServerMetrics metrics;
  SceneStore::Options o;
  o.metrics = &metrics;
  SceneStore store(biker_copies({"a", "b"}), o);
  const nlohmann::json j = nlohmann::json::parse(store.json());
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[1]["name"], "b");
  EXPECT_EQ(j[1]["file"], "b.compressed.ply");
  EXPECT_EQ(j[1]["format"], "compressed_ply");
  EXPECT_EQ(j[1]["gaussians"], 152746);
  EXPECT_EQ(j[1]["sh_degree"], 0);
  EXPECT_TRUE(j[1]["bounds"].is_null()) << "bounds need every mean: unknown before the load";
  EXPECT_EQ(j[1]["loaded"], false);
  EXPECT_EQ(store.loads_started(), 0u);
  EXPECT_EQ(metrics.scenes_loaded.load(), 0);
  store.load_now(1);
  const nlohmann::json after = nlohmann::json::parse(store.json());
  EXPECT_EQ(after[1]["loaded"], true);
  EXPECT_FALSE(after[1]["bounds"].is_null());
  EXPECT_EQ(after[0]["loaded"], false);
  EXPECT_EQ(metrics.scenes_loaded.load(), 1);
  EXPECT_EQ(metrics.scene_bytes.load(), static_cast<std::int64_t>(biker_bytes()));
  EXPECT_EQ(metrics.scene_loads_total.load(), 1u);
}

TEST(SceneStore, RefusesTwoScenesOfOneName) {
  auto sources = biker_copies({"a"});
  sources.push_back(sources[0]);
  EXPECT_THROW(SceneStore(sources, {}), std::runtime_error);
}

// Two sessions ask for one unloaded scene while it loads: one load, one model for both, and each
// sees its progress rise to 100 before the scene.
TEST(SceneStore, WaitersOfOneSceneShareOneLoadAndSeeProgressTo100) {
  Gate gate;
  ServerMetrics metrics;
  SceneStore::Options o;
  o.loader = gate.loader();
  o.metrics = &metrics;
  std::ostringstream log;
  o.log = &log;
  SceneStore store(biker_copies({"a", "b"}), o);
  gate.close();
  Waiter w1, w2;
  auto u1 = store.acquire(1, w1.progress(), w1.ready());
  auto u2 = store.acquire(1, w2.progress(), w2.ready());
  gate.open();
  ASSERT_TRUE(w1.wait());
  ASSERT_TRUE(w2.wait());
  EXPECT_EQ(gate.loads, 1);
  EXPECT_EQ(store.loads_started(), 1u);
  EXPECT_EQ(metrics.scene_loads_total.load(), 1u);
  ASSERT_TRUE(w1.scene && w2.scene);
  EXPECT_EQ(w1.scene.get(), w2.scene.get()) << "one model for both sessions";
  EXPECT_EQ(w1.scene->model->name, "b");
  for (Waiter* w : {&w1, &w2}) {
    ASSERT_GE(w->events.size(), 3u) << "progress before the end";
    EXPECT_EQ(w->events.front(), "p0");
    EXPECT_EQ(w->events[w->events.size() - 2], "p100");
    EXPECT_EQ(w->events.back(), "ready");
    int last = -1;
    for (std::size_t i = 0; i + 1 < w->events.size(); ++i) {
      const int p = std::stoi(w->events[i].substr(1));
      EXPECT_GT(p, last) << "progress must rise";
      last = p;
    }
  }
  // The biker's 152,746 rows report every 8192: the first waiter saw the steps in between.
  EXPECT_GE(w1.events.size(), 10u);
  // The log has a line past each quarter, though no report lands on 25 or 50% (26.8, 53.6).
  std::size_t lines = 0;
  for (std::size_t at = 0; (at = log.str().find(" Gaussians (", at)) != std::string::npos; ++at) ++lines;
  EXPECT_EQ(lines, 3u) << log.str();
  // Once loaded, a third use gets the same scene at once, without another load.
  Waiter w3;
  auto u3 = store.acquire(1, w3.progress(), w3.ready());
  ASSERT_TRUE(w3.wait(0));
  EXPECT_EQ(w3.scene.get(), w1.scene.get());
  EXPECT_EQ(w3.events, std::vector<std::string>{"ready"});
  EXPECT_EQ(gate.loads, 1);
}

// A bad file: its waiter gets an error naming the file; the good scene's waiter is untouched; the
// failure is counted and the next use tries again.
TEST(SceneStore, FailedLoadEndsOnlyItsOwnWaits) {
  auto sources = biker_copies({"good"});
  const std::string bad = fs::path(sources[0].path).parent_path().string() + "/broken.ply";
  {
    std::ofstream f(bad, std::ios::binary);
    f << "ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n"
      << std::string(100, '\0');  // 1000 rows declared, 8 and a bit present
  }
  sources.push_back({bad, ""});
  ServerMetrics metrics;
  SceneStore::Options o;
  o.metrics = &metrics;
  SceneStore store(sources, o);
  Waiter good, broken;
  auto ug = store.acquire(0, good.progress(), good.ready());
  auto ub = store.acquire(1, broken.progress(), broken.ready());
  ASSERT_TRUE(good.wait());
  ASSERT_TRUE(broken.wait());
  ASSERT_TRUE(good.scene);
  EXPECT_FALSE(broken.scene);
  ASSERT_EQ(broken.events.back().rfind("error:", 0), 0u) << broken.events.back();
  EXPECT_NE(broken.events.back().find(bad), std::string::npos) << "the error names the file";
  EXPECT_EQ(metrics.scene_load_failures_total.load(), 1u);
  EXPECT_EQ(metrics.scene_loads_total.load(), 1u);
  EXPECT_EQ(metrics.scenes_loaded.load(), 1);
  ub.reset();
  Waiter again;
  auto ua = store.acquire(1, again.progress(), again.ready());
  ASSERT_TRUE(again.wait());
  EXPECT_FALSE(again.scene);
  EXPECT_EQ(store.loads_started(), 3u) << "a failed scene is tried again on its next use";
}

// A wait withdrawn before the load ends (the session left) gets no callbacks.
TEST(SceneStore, WithdrawnWaitIsNotCalled) {
  Gate gate;
  SceneStore::Options o;
  o.loader = gate.loader();
  SceneStore store(biker_copies({"a"}), o);
  gate.close();
  Waiter gone, stays;
  auto ug = store.acquire(0, gone.progress(), gone.ready());
  auto us = store.acquire(0, stays.progress(), stays.ready());
  ug.reset();
  gate.open();
  ASSERT_TRUE(stays.wait());
  EXPECT_TRUE(stays.scene);
  EXPECT_FALSE(gone.ended);
}

// Budget for one scene and a half: loading a second unloads the unused first; a scene in use is
// kept even over the budget, and unloaded when its last user leaves; least recently used first.
TEST(SceneStore, BudgetUnloadsUnusedScenesLeastRecentlyUsedFirstNeverOneInUse) {
  ServerMetrics metrics;
  SceneStore::Options o;
  o.metrics = &metrics;
  o.budget_bytes = biker_bytes() * 3 / 2;
  std::ostringstream log;
  o.log = &log;
  SceneStore store(biker_copies({"a", "b", "c"}), o);
  auto use = [&](std::size_t i) {
    Waiter w;
    auto u = store.acquire(i, {}, w.ready());
    EXPECT_TRUE(w.wait());
    EXPECT_TRUE(w.scene);
    return u;
  };
  std::weak_ptr<const GaussianModel> a_model;
  {
    auto ua = use(0);
    a_model = store.loaded(0)->model;
  }
  EXPECT_EQ(metrics.scenes_loaded.load(), 1) << "within the budget: a stays after its last user left";
  auto ub = use(1);
  EXPECT_FALSE(store.loaded(0)) << "a, unused, made room for b";
  EXPECT_TRUE(a_model.expired()) << "a's model is freed";
  EXPECT_EQ(metrics.scene_unloads_total.load(), 1u);
  auto uc = use(2);  // b is in use: kept, over the budget
  EXPECT_TRUE(store.loaded(1));
  EXPECT_TRUE(store.loaded(2));
  EXPECT_EQ(metrics.scenes_loaded.load(), 2);
  EXPECT_EQ(metrics.scene_bytes.load(), static_cast<std::int64_t>(2 * biker_bytes()));
  EXPECT_EQ(metrics.scene_unloads_total.load(), 1u);
  EXPECT_NE(log.str().find("over --scene-memory-mb"), std::string::npos) << log.str();
  ub.reset();  // b's last user leaves while over the budget: b goes at once
  EXPECT_FALSE(store.loaded(1));
  EXPECT_TRUE(store.loaded(2));
  EXPECT_EQ(metrics.scene_unloads_total.load(), 2u);
  EXPECT_EQ(metrics.scene_loads_total.load(), 3u);

  // Least recently used first: room for two; a and b loaded and left (b last), then c.
  uc.reset();
  SceneStore::Options two = o;
  two.budget_bytes = biker_bytes() * 5 / 2;
  SceneStore lru(biker_copies({"a", "b", "c"}), two);
  Waiter wa, wb, wc;
  {
    auto u = lru.acquire(0, {}, wa.ready());
    ASSERT_TRUE(wa.wait());
  }
  {
    auto u = lru.acquire(1, {}, wb.ready());
    ASSERT_TRUE(wb.wait());
  }
  auto keep_c = lru.acquire(2, {}, wc.ready());
  ASSERT_TRUE(wc.wait());
  EXPECT_FALSE(lru.loaded(0)) << "a was used least recently";
  EXPECT_TRUE(lru.loaded(1));
  EXPECT_TRUE(lru.loaded(2));
}

// No budget (the default): every scene stays once loaded, as before lazy loading.
TEST(SceneStore, WithoutBudgetEverySceneStays) {
  ServerMetrics metrics;
  SceneStore::Options o;
  o.metrics = &metrics;
  SceneStore store(biker_copies({"a", "b", "c"}), o);
  for (std::size_t i = 0; i < 3; ++i) {
    Waiter w;
    auto u = store.acquire(i, {}, w.ready());
    ASSERT_TRUE(w.wait());
  }
  EXPECT_EQ(metrics.scenes_loaded.load(), 3);
  EXPECT_EQ(metrics.scene_unloads_total.load(), 0u);
}

}  // namespace

namespace {

// `--scene DIR` (issue 20): the folder's scene files in name order, SOG folders as their
// meta.json, nothing deeper, no other files and no dangling links; a SOG folder itself is one scene; an empty folder
// is an error naming it.
TEST(SceneFolder, ListsItsScenesInNameOrder) {
  const fs::path dir = fs::path(test::temp_dir()) / "scenes";
  for (const char* f : {"b.spz", "a.compressed.ply", "c.GLB", "notes.txt", "sog/meta.json", "deep/x/y.ply"}) {
    fs::create_directories((dir / f).parent_path());
    std::ofstream(dir / f) << "x";
  }
  fs::create_symlink(dir / "gone.ply", dir / "broken.ply");  // a dangling link is skipped
  const std::vector<std::string> want = {(dir / "a.compressed.ply").string(), (dir / "b.spz").string(),
                                         (dir / "c.GLB").string(), (dir / "sog/meta.json").string()};
  EXPECT_EQ(scenes_in_folder(dir.string()), want);
  EXPECT_EQ(scenes_in_folder((dir / "sog").string()), std::vector<std::string>{(dir / "sog/meta.json").string()});

  ServerOptions o;
  const std::string d = dir.string(), extra = "/elsewhere/z.ply";
  const char* argv[] = {"catgs-server", "--scene", d.c_str(), "--scene", extra.c_str()};
  ASSERT_TRUE(parse_server_options(5, const_cast<char**>(argv), o));
  EXPECT_EQ(o.store.scene, want[0]);
  EXPECT_EQ(o.store.more_scenes, (std::vector<std::string>{want[1], want[2], want[3], extra}));

  const fs::path empty = fs::path(test::temp_dir()) / "empty";
  fs::create_directories(empty / "deep");
  std::ofstream(empty / "readme.md") << "x";
  try {
    scenes_in_folder(empty.string());
    ADD_FAILURE() << "an empty folder gave scenes";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(empty.string()), std::string::npos) << e.what();
  }
}

}  // namespace
