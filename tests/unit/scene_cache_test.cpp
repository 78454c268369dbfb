// Issue 37, loading: the parallel PLY reader against the serial reference reader on the real
// scenes, its errors and progress, and the scene cache (the same model bit for bit, the GPU
// layout, and every way a cache is rejected and rebuilt).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "forward_model/chunk_bounds.h"
#include "forward_model/sh_storage.h"
#include "scene/ply_io.h"
#include "scene/scene_cache.h"
#include "test_data.h"

namespace catgs {
namespace {

namespace fs = std::filesystem;

template <typename T, typename A>
bool same_bits(const std::vector<T, A>& a, const std::vector<T, A>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// Bit-for-bit equality of two models (NaN-safe, -0 vs 0 told apart).
void expect_same_model(const GaussianModel& a, const GaussianModel& b, const std::string& what) {
  EXPECT_EQ(a.name, b.name) << what;
  EXPECT_EQ(a.sh_degree, b.sh_degree) << what;
  EXPECT_EQ(a.size(), b.size()) << what;
  EXPECT_TRUE(same_bits(a.means, b.means)) << what << ": means";
  EXPECT_TRUE(same_bits(a.log_scales, b.log_scales)) << what << ": log-scales";
  EXPECT_TRUE(same_bits(a.rotations, b.rotations)) << what << ": rotations";
  EXPECT_TRUE(same_bits(a.opacity_logits, b.opacity_logits)) << what << ": opacities";
  EXPECT_TRUE(same_bits(a.sh, b.sh)) << what << ": SH";
}

// The real scenes: three INRIA PLY files of SH degree 3 and 2 and two compressed PLY files.
std::vector<std::string> real_scenes() {
  std::vector<std::string> out{test::bundled_scene()};
  for (const char* s : {"scenes/flowers_sh3.ply", "scenes/tumblewood_sh2.ply", "scenes/guitar.compressed.ply"}) {
    const std::string p = test::data_file(s);
    if (!p.empty()) out.push_back(p);
  }
  return out;
}

std::string copy_to(const std::string& from, const std::string& dir) {
  const std::string to = (fs::path(dir) / fs::path(from).filename()).string();
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
  fs::permissions(to, fs::perms::owner_read | fs::perms::owner_write, fs::perm_options::add);
  return to;
}

TEST(ParallelLoad, EqualsTheSerialReferenceOnRealScenes) {
  const auto scenes = real_scenes();
  if (scenes.size() < 4) GTEST_SKIP() << "real data not found under CATGS_DATA_DIR (" << test::data_dir() << ")";
  for (const std::string& path : scenes) {
    LoadOptions ref;
    ref.reference = true;
    const GaussianModel reference = load_scene(path, ref);
    // 1 thread takes the fast float32 path alone; 3 and 8 split the blocks unevenly.
    for (int threads : {1, 3, 8}) {
      LoadOptions o;
      o.threads = threads;
      expect_same_model(load_scene(path, o), reference, path + " with " + std::to_string(threads) + " threads");
    }
  }
}

// A PLY of n Gaussians (SH degree 1) with values the tests below break.
GaussianModel small_model(std::size_t n) {
  GaussianModel m;
  m.sh_degree = 1;
  m.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      m.means[3 * i + a] = static_cast<float>(i % 97) * 0.01f + static_cast<float>(a);
      m.log_scales[3 * i + a] = -3.0f;
    }
    m.rotations[4 * i] = 1.0f;
    m.opacity_logits[i] = static_cast<float>(i % 7) - 3.0f;
    for (std::size_t k = 0; k < 12; ++k) m.sh[12 * i + k] = 0.01f * static_cast<float>(k);
  }
  return m;
}

// Overwrites float `property` (its index among the file's properties) of row `row`.
void poke_float(const std::string& path, std::size_t row, int property, float value) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const std::size_t body = text.find("end_header\n") + 11;
  std::size_t properties = 0;
  for (std::size_t at = 0; (at = text.find("\nproperty ", at)) < body; ++at) ++properties;
  f.seekp(static_cast<std::streamoff>(body + (row * properties + static_cast<std::size_t>(property)) * 4));
  f.write(reinterpret_cast<const char*>(&value), 4);
}

// The first bad row in file order is named, whichever thread meets it first: two bad rows in
// different blocks (8192 rows each), the later block's met first by its thread when it races
// ahead; the message is the serial reader's.
TEST(ParallelLoad, NamesTheFirstBadRowAsTheSerialReaderDoes) {
  const std::string dir = test::temp_dir(), path = dir + "/bad.ply";
  write_inria_ply(small_model(40000), path);
  poke_float(path, 30000, 0, NAN);       // x of a row in block 3
  poke_float(path, 9000, 13, INFINITY);  // f_rest_4 (after x y z nx ny nz f_dc x3) in block 1
  auto message = [&](const LoadOptions& o) {
    try {
      (void)load_scene(path, o);
    } catch (const SceneFileError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  LoadOptions ref;
  ref.reference = true;
  const std::string expected = message(ref);
  EXPECT_NE(expected.find("row 9000 property 'f_rest_4'"), std::string::npos) << expected;
  EXPECT_NE(expected.find(path), std::string::npos) << expected;
  for (int threads : {1, 2, 4, 16}) EXPECT_EQ(message(LoadOptions{threads, false}), expected) << threads;
}

// Progress comes on the calling thread, rising, ending at (N, N); a callback that throws (a
// stopping server) stops the load with its exception.
TEST(ParallelLoad, ProgressOnTheLoadingThreadAndCancellable) {
  CATGS_REQUIRE_DATA(path, "scenes/tumblewood_sh2.ply");
  const auto caller = std::this_thread::get_id();
  std::vector<std::pair<uint64_t, uint64_t>> calls;
  bool other_thread = false;
  const GaussianModel m = load_scene(path, LoadOptions{4, false}, [&](uint64_t done, uint64_t total) {
    other_thread |= std::this_thread::get_id() != caller;
    calls.emplace_back(done, total);
  });
  EXPECT_FALSE(other_thread);
  ASSERT_GE(calls.size(), 2u);
  for (std::size_t k = 1; k < calls.size(); ++k) EXPECT_GT(calls[k].first, calls[k - 1].first);
  EXPECT_EQ(calls.back().first, m.size());
  EXPECT_EQ(calls.back().second, m.size());
  int seen = 0;
  EXPECT_THROW(load_scene(path, LoadOptions{4, false},
                          [&](uint64_t, uint64_t) {
                            if (++seen == 2) throw std::runtime_error("stop");
                          }),
               std::runtime_error);
}

struct Loaded {
  GaussianModel model;
  CachedLoadReport report;
  std::vector<std::string> log;
};
Loaded load_cached(const std::string& path, SceneCacheMode mode = SceneCacheMode::write) {
  Loaded out;
  CachedLoadOptions o;
  o.mode = mode;
  o.log = [&](const std::string& line) { out.log.push_back(line); };
  out.model = load_scene_cached(path, o, {}, &out.report);
  return out;
}
bool logged(const Loaded& l, const std::string& part) {
  for (const auto& line : l.log)
    if (line.find(part) != std::string::npos) return true;
  return false;
}

// The cache gives the plain load's model bit for bit, and holds the layout DeviceScene uploads:
// the SH rounded by fm::half_bits and fm::chunk_bounds of the model.
TEST(SceneCache, CachedLoadEqualsThePlainLoadAndHoldsTheGpuLayout) {
  const auto scenes = real_scenes();
  if (scenes.size() < 4) GTEST_SKIP() << "real data not found under CATGS_DATA_DIR (" << test::data_dir() << ")";
  const std::string dir = test::temp_dir();
  for (const std::string& original : scenes) {
    const std::string path = copy_to(original, dir);
    const GaussianModel plain = load_scene(path);
    const Loaded first = load_cached(path);
    EXPECT_FALSE(first.report.from_cache);
    EXPECT_TRUE(first.report.written) << path;
    EXPECT_TRUE(logged(first, "no cache file")) << path;
    const Loaded second = load_cached(path);
    EXPECT_TRUE(second.report.from_cache) << second.report.why;
    EXPECT_FALSE(second.report.written);
    expect_same_model(second.model, plain, path + " through the cache");

    const auto cache = SceneCache::open(scene_cache_path(path), path);
    const GaussianModel again = cache->read_model(3);
    expect_same_model(again, plain, path + " read_model");
    std::vector<uint16_t> half(plain.sh.size());
    for (std::size_t k = 0; k < half.size(); ++k) half[k] = fm::half_bits(plain.sh[k]);
    EXPECT_EQ(std::memcmp(cache->sh_half(), half.data(), 2 * half.size()), 0) << path;
    const auto chunks = chunk_bounds_of(plain);
    EXPECT_EQ(std::memcmp(cache->chunks(), chunks.data(), chunks.size() * sizeof(fm::ChunkBounds)), 0) << path;
  }
}

// Each damaged cache: rejected with the reason logged, the scene read, the cache rewritten, and
// the next load served from it.
TEST(SceneCache, DamagedCachesAreRejectedAndRebuilt) {
  const std::string dir = test::temp_dir();
  const std::string path = copy_to(test::bundled_scene(), dir), cache = scene_cache_path(path);
  const GaussianModel plain = load_scene(path);
  ASSERT_TRUE(load_cached(path).report.written);
  const auto good_size = fs::file_size(cache);

  auto patch = [&](uint64_t offset, const std::string& bytes) {
    std::fstream f(cache, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(offset));
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  };
  auto flip = [&](uint64_t offset) {
    char b = 0;
    {
      std::ifstream in(cache, std::ios::binary);
      in.seekg(static_cast<std::streamoff>(offset));
      in.read(&b, 1);
    }
    patch(offset, std::string(1, static_cast<char>(~b)));
  };
  struct Case {
    const char* name;
    std::function<void()> damage;
    const char* reason;
  };
  const uint32_t other_version = kSceneCacheVersion + 1;
  const std::vector<Case> cases = {
      {"truncated", [&] { fs::resize_file(cache, good_size - 5000); }, "truncated"},
      {"shorter than a header", [&] { fs::resize_file(cache, 100); }, "shorter than a header"},
      // 40000 bytes from the end: inside the half SH, before the chunk bounds' 20 KB.
      {"a byte of the half SH flipped", [&] { flip(good_size - 40000); }, "checksum mismatch in section sh_half"},
      {"a byte of the means flipped", [&] { flip(3 * 4096 + 100); }, "checksum mismatch in section means"},
      {"another version", [&] { patch(8, std::string(reinterpret_cast<const char*>(&other_version), 4)); },
       "cache version"},
      {"the header's count changed", [&] { patch(20, std::string(1, '\x07')); }, "header checksum mismatch"},
      {"not a cache", [&] { std::ofstream(cache) << std::string(8192, 'x'); }, "not a scene cache"},
      {"missing", [&] { fs::remove(cache); }, "no cache file"},
  };
  for (const Case& c : cases) {
    c.damage();
    const Loaded l = load_cached(path);
    EXPECT_FALSE(l.report.from_cache) << c.name;
    EXPECT_NE(l.report.why.find(c.reason), std::string::npos) << c.name << ": " << l.report.why;
    EXPECT_TRUE(logged(l, c.reason)) << c.name;
    EXPECT_TRUE(l.report.written) << c.name;
    expect_same_model(l.model, plain, c.name);
    EXPECT_EQ(fs::file_size(cache), good_size) << c.name;
    EXPECT_TRUE(load_cached(path).report.from_cache) << c.name << ": rebuilt";
  }
  // Read-only mode uses nothing it cannot trust and writes nothing.
  fs::resize_file(cache, good_size - 1);
  const Loaded ro = load_cached(path, SceneCacheMode::read);
  EXPECT_FALSE(ro.report.from_cache);
  EXPECT_FALSE(ro.report.written);
  EXPECT_EQ(fs::file_size(cache), good_size - 1);
}

void set_mtime(const std::string& path, const struct timespec& t) {
  const struct timespec times[2] = {t, t};
  ASSERT_EQ(::utimensat(AT_FDCWD, path.c_str(), times, 0), 0);
}
struct timespec mtime_of(const std::string& path) {
  struct stat st {};
  ::stat(path.c_str(), &st);
  return st.st_mtim;
}

// A changed source invalidates its cache: a new modification time, a new size, or a header that
// changed while size and time were put back.
TEST(SceneCache, AChangedSourceInvalidatesTheCache) {
  const std::string dir = test::temp_dir();
  const std::string path = copy_to(test::bundled_scene(), dir);
  ASSERT_TRUE(load_cached(path).report.written);

  const struct timespec t0 = mtime_of(path);
  set_mtime(path, {t0.tv_sec + 10, t0.tv_nsec});
  Loaded l = load_cached(path);
  EXPECT_NE(l.report.why.find("the source changed (modification time)"), std::string::npos) << l.report.why;
  EXPECT_TRUE(load_cached(path).report.from_cache);

  // The same size and time, another header: "comment" -> "COMMENT" is not a PLY keyword, so make
  // it a comment with other text instead (the writer's first comment line).
  std::string text;
  {
    std::ifstream in(path, std::ios::binary);
    text.assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  const std::size_t at = text.find("comment ");
  ASSERT_NE(at, std::string::npos) << "the bundled scene has a comment line";
  const struct timespec t1 = mtime_of(path);
  text[at + 8] = text[at + 8] == 'X' ? 'Y' : 'X';
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
  set_mtime(path, t1);
  l = load_cached(path);
  EXPECT_NE(l.report.why.find("the source changed (its header)"), std::string::npos) << l.report.why;
  EXPECT_TRUE(load_cached(path).report.from_cache);

  // Another scene in its place (another size).
  fs::copy_file(test::data_file("scenes/guitar.compressed.ply").empty()
                    ? test::bundled_scene()
                    : test::data_file("scenes/guitar.compressed.ply"),
                path, fs::copy_options::overwrite_existing);
  if (fs::file_size(path) != text.size()) {
    l = load_cached(path);
    EXPECT_NE(l.report.why.find("the source changed (size"), std::string::npos) << l.report.why;
    expect_same_model(l.model, load_scene(path), "the new source");
  }
}

// A folder that cannot be written: the load goes on, the failure logged.
TEST(SceneCache, UnwritableFolderIsLoggedAndTheLoadGoesOn) {
  const std::string dir = test::temp_dir();
  const std::string path = copy_to(test::bundled_scene(), dir);
  CachedLoadOptions o;
  o.cache_path = dir + "/no/such/folder/x.catgs-cache";
  std::vector<std::string> log;
  o.log = [&](const std::string& line) { log.push_back(line); };
  CachedLoadReport report;
  const GaussianModel m = load_scene_cached(path, o, {}, &report);
  EXPECT_EQ(m.size(), load_scene(path).size());
  EXPECT_FALSE(report.written);
  ASSERT_FALSE(log.empty());
  EXPECT_NE(log.back().find("not written"), std::string::npos) << log.back();
}

}  // namespace
}  // namespace catgs
