// The scene a server serves, with its level of detail (issue 46, process/scene_with_lod.h): a
// missing LOD file is built and written, then read back instead of rebuilt; a stale or foreign
// one is rebuilt, not trusted; read mode writes nothing; off serves the scene alone. On copies of
// the bundled biker scene (always present). The built model's leaves are checked against the
// scene read on its own (load_scene), the written file against a fresh build.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "lod/lod_build.h"
#include "scene/compact_file.h"
#include "scene/ply_io.h"
#include "scene/scene_peek.h"
#include "process/scene_with_lod.h"
#include "server_options.h"
#include "test_data.h"

namespace {

using namespace catgs;
using namespace catgs::server;
namespace fs = std::filesystem;

struct LoadRun {
  std::vector<std::string> log;
  std::vector<std::pair<uint64_t, uint64_t>> progress;
  GaussianModel model;
  bool said(const std::string& text) const {
    for (const std::string& line : log)
      if (line.find(text) != std::string::npos) return true;
    return false;
  }
};

LoadRun load(const std::string& path, LodMode mode, ServerMetrics* metrics, const std::string& cache_dir = "",
             std::uint64_t min_gaussians = 0) {
  LoadRun r;
  SceneWithLodOptions o;
  o.lod = mode;
  o.cache_dir = cache_dir;
  o.min_gaussians = min_gaussians;
  o.cache = SceneCacheMode::off;
  o.metrics = metrics;
  o.log = [&r](const std::string& line) { r.log.push_back(line); };
  r.model = load_scene_with_lod(path, o, [&r](uint64_t done, uint64_t total) { r.progress.push_back({done, total}); });
  return r;
}

std::string scene_copy(const std::string& dir, const std::string& name) {
  const std::string path = dir + "/" + name + ".compressed.ply";
  fs::copy_file(test::bundled_scene(), path, fs::copy_options::overwrite_existing);
  return path;
}

// The leaves of a LOD model hold the scene's Gaussians (in Morton order or the scene's own, then
// padding): the same multiset of means, compared as sorted triples.
void expect_leaves_are(const GaussianModel& lod, const GaussianModel& scene) {
  ASSERT_FALSE(lod.lod.empty());
  const std::size_t leaves = lod_leaf_gaussians(lod);
  ASSERT_GE(leaves, scene.size());
  ASSERT_LT(leaves, scene.size() + 256);
  auto sorted_means = [](const GaussianModel& m, std::size_t n) {
    std::vector<std::array<float, 3>> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = {m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]};
    std::sort(v.begin(), v.end());
    return v;
  };
  // Padding (lod_build.h): after the scene's Gaussians, invisible (opacity logit
  // -kOpacityLogitLimit).
  std::vector<std::array<float, 3>> got;
  for (std::size_t i = 0; i < leaves; ++i) {
    if (i >= scene.size()) {
      EXPECT_EQ(lod.opacity_logits[i], -kOpacityLogitLimit) << i;
      continue;
    }
    got.push_back({lod.means[3 * i], lod.means[3 * i + 1], lod.means[3 * i + 2]});
  }
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, sorted_means(scene, scene.size()));
}

// A LOD the server wrote is served as its file will give it (compact_file.h): the build of
// `scene` (read from `path`), quantized; a compressed PLY is built in its own order.
void expect_quantized_build(const GaussianModel& served, const std::string& path) {
  const GaussianModel scene = load_scene(path);
  LodBuildOptions o;
  o.keep_order = peek_scene(path).format == "compressed_ply";
  GaussianModel want = build_lod(scene, o);
  quantize_compact(want);
  test::expect_same_gaussians(served, want);
  ASSERT_EQ(served.lod.size(), want.lod.size());
  EXPECT_EQ(std::memcmp(served.lod.data(), want.lod.data(), want.lod.size() * sizeof(fm::LodNode)), 0);
}

TEST(SceneWithLod, MissingFileIsBuiltWrittenThenRead) {
  const std::string dir = test::temp_dir(), path = scene_copy(dir, "a");
  ServerMetrics metrics;
  const LoadRun first = load(path, LodMode::write, &metrics);
  EXPECT_TRUE(first.said("LOD file not used")) << first.log.front();
  EXPECT_TRUE(first.said("level of detail built"));
  EXPECT_TRUE(fs::exists(path + ".catgs-lod"));
  EXPECT_EQ(metrics.lod_builds_total.load(), 1u);
  EXPECT_EQ(metrics.lod_files_written_total.load(), 1u);
  EXPECT_EQ(metrics.lod_builds_running.load(), 0);
  EXPECT_EQ(metrics.lod_build_permille.load(), 1000);
  expect_quantized_build(first.model, path);
  // Progress rises to its end: the read is the first half, the build the second.
  ASSERT_FALSE(first.progress.empty());
  for (std::size_t i = 1; i < first.progress.size(); ++i) {
    EXPECT_GE(first.progress[i].first * first.progress[i - 1].second,
              first.progress[i - 1].first * first.progress[i].second)
        << "progress fell at report " << i;
  }
  EXPECT_EQ(first.progress.back().first, first.progress.back().second);

  const LoadRun second = load(path, LodMode::write, &metrics);
  EXPECT_TRUE(second.said("level of detail from")) << second.log.front();
  EXPECT_EQ(metrics.lod_builds_total.load(), 1u) << "a valid LOD file was rebuilt";
  EXPECT_EQ(second.model.means, first.model.means);
  EXPECT_EQ(second.model.sh, first.model.sh);
  ASSERT_EQ(second.model.lod.size(), first.model.lod.size());
  for (std::size_t c = 0; c < first.model.lod.size(); ++c) {
    EXPECT_EQ(second.model.lod[c].error, first.model.lod[c].error) << "node " << c;
    EXPECT_EQ(second.model.lod[c].parent, first.model.lod[c].parent) << "node " << c;
  }
}

TEST(SceneWithLod, StaleOrForeignFileIsRebuiltNotTrusted) {
  const std::string dir = test::temp_dir(), a = scene_copy(dir, "a"), b = dir + "/b.ply";
  ServerMetrics metrics;
  (void)load(a, LodMode::write, &metrics);
  // The scene changes after its LOD file was written (a newer capture copied over it).
  fs::last_write_time(a, fs::last_write_time(a) + std::chrono::hours(1));
  const LoadRun stale = load(a, LodMode::write, &metrics);
  EXPECT_TRUE(stale.said("LOD file not used")) << stale.log.front();
  EXPECT_EQ(metrics.lod_builds_total.load(), 2u);
  EXPECT_TRUE(load(a, LodMode::write, &metrics).said("level of detail from")) << "the rebuilt file was not kept";

  // Another scene's LOD file put beside this one.
  const GaussianModel other = load_scene(test::bundled_scene());
  GaussianModel shifted = other;
  for (float& m : shifted.means) m += 1.0f;
  write_inria_ply(shifted, b);
  fs::copy_file(a + ".catgs-lod", b + ".catgs-lod", fs::copy_options::overwrite_existing);
  const LoadRun foreign = load(b, LodMode::write, &metrics);
  EXPECT_TRUE(foreign.said("LOD file not used")) << foreign.log.front();
  expect_quantized_build(foreign.model, b);
  EXPECT_EQ(metrics.lod_builds_total.load(), 3u);
}

TEST(SceneWithLod, ReadWritesNothingAndOffServesTheScene) {
  const std::string dir = test::temp_dir(), path = scene_copy(dir, "a");
  ServerMetrics metrics;
  const LoadRun read = load(path, LodMode::read, &metrics);
  EXPECT_FALSE(fs::exists(path + ".catgs-lod"));
  EXPECT_EQ(metrics.lod_files_written_total.load(), 0u);
  expect_leaves_are(read.model, load_scene(path));
  const LoadRun off = load(path, LodMode::off, &metrics);
  EXPECT_TRUE(off.model.lod.empty());
  EXPECT_EQ(off.model.means, load_scene(path).means);
}

// Issue 74: a compact scene with its level of detail is served alone: nothing built, cached or
// written; --lod off serves its leaves.
TEST(SceneWithLod, CompactSceneIsServedAlone) {
  const std::string dir = test::temp_dir(), cache = dir + "/cache", path = dir + "/city.catgs";
  GaussianModel lod = build_lod(load_scene(test::bundled_scene()));
  write_compact_scene(lod, path);
  quantize_compact(lod);
  ServerMetrics metrics;
  const LoadRun served = load(path, LodMode::write, &metrics, cache);
  EXPECT_TRUE(served.said("level of detail from the compact scene")) << served.log.back();
  EXPECT_EQ(served.model.means, lod.means);
  EXPECT_EQ(served.model.lod.size(), lod.lod.size());
  EXPECT_EQ(metrics.lod_builds_total.load(), 0u);
  EXPECT_FALSE(fs::exists(cache)) << "a file was written for a compact scene";
  const LoadRun off = load(path, LodMode::off, &metrics, cache);
  EXPECT_TRUE(off.model.lod.empty());
  EXPECT_EQ(off.model.size(), lod_leaf_gaussians(lod));
  EXPECT_EQ(off.model.means, ModelArray(lod.means.begin(), lod.means.begin() + 3 * off.model.size()));
}

TEST(SceneWithLod, Options) {
  EXPECT_EQ(parse_lod_mode("off"), LodMode::off);
  EXPECT_EQ(parse_lod_mode("write"), LodMode::write);
  EXPECT_THROW(parse_lod_mode("on"), std::invalid_argument);
  const char* argv[] = {"catgs-server", "--lod", "sometimes"};
  ServerOptions options;
  EXPECT_EQ(options.store.lod, "write");
  EXPECT_GT(options.session.frame.lod.bound_px, 0.0f);
  try {
    (void)parse_server_options(3, const_cast<char**>(argv), options);
    ADD_FAILURE() << "--lod sometimes accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("--lod"), std::string::npos) << e.what();
  }
}

// Issue 61: derived files go to the cache folder, named by the scene's content, never beside
// the user's scene; a LOD file beside it (catgs-scene lod's) is still served; a scene under
// min_gaussians is served as it is, nothing built or written.
TEST(SceneWithLod, DerivedFilesGoToTheCacheFolder) {
  const std::string dir = test::temp_dir(), path = scene_copy(dir, "a"), cache = dir + "/cache/catgs";
  ServerMetrics metrics;
  const LoadRun first = load(path, LodMode::write, &metrics, cache);
  const std::string in_folder = derived_file_path(path, ".catgs-lod", cache);
  EXPECT_TRUE(first.said("LOD file written to " + in_folder)) << first.log.back();
  EXPECT_TRUE(fs::exists(in_folder)) << "the folder was not made, or the file not written there";
  EXPECT_FALSE(fs::exists(path + ".catgs-lod")) << "written beside the user's scene";
  const LoadRun second = load(path, LodMode::write, &metrics, cache);
  EXPECT_TRUE(second.said("level of detail from " + in_folder)) << second.log.front();
  EXPECT_EQ(metrics.lod_builds_total.load(), 1u);

  // The same content under another name in another folder: its own file (the name leads it);
  // the same name with other content: another key.
  const std::string other_dir = dir + "/other";
  fs::create_directories(other_dir);
  const std::string same_name = scene_copy(other_dir, "a");
  const std::string p1 = derived_file_path(path, ".catgs-lod", cache),
                    p2 = derived_file_path(same_name, ".catgs-lod", cache);
  EXPECT_EQ(p1, p2) << "one content, one name: the same derived file";
  const GaussianModel scene = load_scene(path);
  GaussianModel shifted = scene;
  for (float& m : shifted.means) m += 1.0f;
  const std::string changed = other_dir + "/b.ply";
  write_inria_ply(shifted, changed);
  fs::copy_file(changed, other_dir + "/a.compressed.ply", fs::copy_options::overwrite_existing);
  EXPECT_NE(derived_file_path(other_dir + "/a.compressed.ply", ".catgs-lod", cache), p1);
  EXPECT_EQ(derived_file_path(path, ".catgs-lod", ""), path + ".catgs-lod") << "no folder: beside the scene";

  // A LOD file beside a scene, the folder holding none: served from beside.
  const std::string beside = scene_copy(dir, "c");
  (void)load(beside, LodMode::write, &metrics);  // no folder: written beside
  ASSERT_TRUE(fs::exists(beside + ".catgs-lod"));
  const LoadRun from_beside = load(beside, LodMode::write, &metrics, cache);
  EXPECT_TRUE(from_beside.said("level of detail from " + beside + ".catgs-lod")) << from_beside.log.front();
}

TEST(SceneWithLod, SmallSceneIsServedWithoutBuildingALevelOfDetail) {
  const std::string dir = test::temp_dir(), path = scene_copy(dir, "a"), cache = dir + "/cache";
  ServerMetrics metrics;
  const GaussianModel scene = load_scene(path);
  const LoadRun small = load(path, LodMode::write, &metrics, cache, scene.size() + 1);
  EXPECT_TRUE(small.said("served without a level of detail")) << small.log.back();
  EXPECT_TRUE(small.model.lod.empty());
  EXPECT_EQ(small.model.means, scene.means);
  EXPECT_EQ(metrics.lod_builds_total.load(), 0u);
  EXPECT_FALSE(fs::exists(derived_file_path(path, ".catgs-lod", cache)));
  EXPECT_FALSE(fs::exists(path + ".catgs-lod"));
  ASSERT_FALSE(small.progress.empty());
  EXPECT_EQ(small.progress.back().first, small.progress.back().second) << "progress ends at its end";
  // At the threshold: built.
  const LoadRun at = load(path, LodMode::write, &metrics, cache, scene.size());
  EXPECT_FALSE(at.model.lod.empty());
}

TEST(SceneWithLod, DefaultCacheFolderFollowsXdg) {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  const std::string saved = xdg ? xdg : "";
  ::setenv("XDG_CACHE_HOME", "/var/tmp/xdg", 1);
  EXPECT_EQ(default_cache_folder(), "/var/tmp/xdg/catgs");
  ::setenv("XDG_CACHE_HOME", "relative/ignored", 1);
  const char* home = std::getenv("HOME");
  if (home && *home) EXPECT_EQ(default_cache_folder(), std::string(home) + "/.cache/catgs");
  if (xdg)
    ::setenv("XDG_CACHE_HOME", saved.c_str(), 1);
  else
    ::unsetenv("XDG_CACHE_HOME");
}

}  // namespace
