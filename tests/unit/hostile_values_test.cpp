// Issue 49: a scene cache or LOD file beside a scene is held to the scene's own checks, and the
// render cores draw a finite image of any model a reader accepts.
//
// The oracle is the scene's own loader: a value is refused from a cache exactly when the INRIA
// PLY reader (its per-row check) and GaussianModel::validate refuse it. The forger is an attacker
// with write access to the folder: write_scene_cache writes any model, and reseal_scene_cache
// recomputes every hash of a file patched byte by byte (XXH3 proves integrity, not authorship).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../common/hostile_values.h"
#include "cpu/cpu_renderer.h"
#include "camera/trace.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"
#include "scene/scene_bounds.h"
#include "scene/scene_cache.h"
#include "lod/lod_build.h"
#include "test_data.h"

namespace catgs {
namespace {

namespace fs = std::filesystem;

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

// The bundled scene copied into a fresh folder (a cache is written beside it).
std::string scene_copy() {
  const std::string path = test::temp_dir() + "/biker.compressed.ply";
  fs::copy_file(test::bundled_scene(), path, fs::copy_options::overwrite_existing);
  fs::permissions(path, fs::perms::owner_read | fs::perms::owner_write, fs::perm_options::add);
  return path;
}

CachedLoadReport load_read_only(const std::string& path, GaussianModel* out, std::vector<std::string>* log) {
  CachedLoadOptions o;
  o.mode = SceneCacheMode::read;
  o.log = [log](const std::string& line) { log->push_back(line); };
  CachedLoadReport report;
  *out = load_scene_cached(path, o, {}, &report);
  return report;
}

// The same hostile values in an INRIA PLY: does the scene's own loader take them?
bool ply_loader_accepts(const GaussianModel& m, const std::string& dir) {
  const std::string ply = dir + "/hostile.ply";
  write_inria_ply(m, ply);
  try {
    (void)load_scene(ply);
    return true;
  } catch (const SceneFileError&) {
    return false;
  }
}

// Every hostile case forged into a cache (every 7th Gaussian from Gaussian 3): refused exactly
// when the PLY loader refuses the same values, with the cache named and the first bad Gaussian
// and property said, and the scene then read from its own file as if no cache were there.
TEST(ForgedSceneCache, RefusedExactlyWhenTheSceneLoaderRefuses) {
  const std::string path = scene_copy(), cache = scene_cache_path(path), dir = fs::path(path).parent_path();
  const GaussianModel plain = load_scene(path);
  for (const test::HostileCase& c : test::hostile_cases()) {
    GaussianModel forged = plain;
    test::apply_hostile(forged, c, 3);
    write_scene_cache(forged, path, cache);
    GaussianModel got;
    std::vector<std::string> log;
    const CachedLoadReport r = load_read_only(path, &got, &log);
    // +-inf opacity logits in a PLY are clamped by its reader (kOpacityLogitLimit); as a value in
    // the model they are what validate refuses.
    const bool ply_clamps = c.property == test::HostileProperty::opacity && std::isinf(c.value);
    if (!ply_clamps) {
      EXPECT_EQ(ply_loader_accepts(forged, dir), !c.refused) << c.name;
    }
    EXPECT_EQ(r.from_cache, !c.refused) << c.name << ": " << r.why;
    if (c.refused) {
      EXPECT_NE(r.why.find(cache), std::string::npos) << c.name << ": " << r.why;
      EXPECT_NE(r.why.find(std::string(c.reason) + " of Gaussian 3"), std::string::npos) << c.name << ": " << r.why;
      ASSERT_FALSE(log.empty()) << c.name;
      EXPECT_NE(log.front().find(c.reason), std::string::npos) << c.name << ": " << log.front();
      EXPECT_EQ(got.means, plain.means) << c.name << ": the scene itself was read";
      EXPECT_EQ(got.sh, plain.sh) << c.name;
      EXPECT_NO_THROW(got.validate()) << c.name;
    }
  }
}

// A cache patched byte by byte and resealed: the hashes then pass, and the value check is what
// stops it. An unpatched resealed cache is still used (the reseal itself changes nothing).
TEST(ForgedSceneCache, ResealedPatchesReachTheValueCheck) {
  const std::string path = scene_copy(), cache = scene_cache_path(path);
  write_scene_cache(load_scene(path), path, cache);
  const std::string good = read_file(cache);
  GaussianModel got;
  std::vector<std::string> log;

  std::string bytes = good;
  reseal_scene_cache(bytes, path);
  EXPECT_EQ(bytes, good) << "resealing an intact cache changes no byte";

  // 12 KiB in: inside the means section (after the 4 KiB header and the hash table's page).
  const float nan = std::nanf("");
  bytes = good;
  std::memcpy(&bytes[3 * 4096], &nan, 4);
  write_file(cache, bytes);
  CachedLoadReport r = load_read_only(path, &got, &log);
  EXPECT_NE(r.why.find("checksum mismatch in section means"), std::string::npos) << r.why;
  reseal_scene_cache(bytes, path);
  write_file(cache, bytes);
  r = load_read_only(path, &got, &log);
  EXPECT_FALSE(r.from_cache);
  EXPECT_NE(r.why.find("non-finite mean of Gaussian"), std::string::npos) << r.why;

  // A finite patch, resealed, is used: the check refuses what a loader refuses, nothing more.
  const float far = 1e30f;
  bytes = good;
  std::memcpy(&bytes[3 * 4096], &far, 4);
  reseal_scene_cache(bytes, path);
  write_file(cache, bytes);
  r = load_read_only(path, &got, &log);
  EXPECT_TRUE(r.from_cache) << r.why;
}

// A LOD file whose merged levels hold a value the loader refuses is refused, naming the file and
// the merged Gaussian; a tree with a non-finite box too. The leaves were checked by the scene's
// load; the merged levels come only from the file.
TEST(ForgedLodFile, MergedLevelsHeldToTheSameCheck) {
  const std::string path = scene_copy(), lod_path = path + ".catgs-lod";
  // The scene's first 64 chunks: a LOD build in well under a second.
  const GaussianModel full = load_scene(path);
  const std::size_t n = 64 * fm::kChunkSize, k = static_cast<std::size_t>(full.sh_coeffs()) * 3;
  GaussianModel leaves;
  leaves.sh_degree = full.sh_degree;
  leaves.resize(n);
  std::copy_n(full.means.begin(), 3 * n, leaves.means.begin());
  std::copy_n(full.log_scales.begin(), 3 * n, leaves.log_scales.begin());
  std::copy_n(full.rotations.begin(), 4 * n, leaves.rotations.begin());
  std::copy_n(full.opacity_logits.begin(), n, leaves.opacity_logits.begin());
  std::copy_n(full.sh.begin(), k * n, leaves.sh.begin());
  const GaussianModel lod = build_lod(leaves);
  const std::size_t merged = lod_leaf_gaussians(lod);
  ASSERT_LT(merged, lod.size()) << "the build made merged levels";
  write_scene_cache(lod, path, lod_path);
  EXPECT_EQ(load_lod_file(lod_path, path).size(), lod.size());

  for (const test::HostileCase& c : test::hostile_cases()) {
    if (!c.refused) continue;
    GaussianModel forged = lod;
    test::apply_hostile(forged, c, merged + 5, forged.size());  // one merged Gaussian
    write_scene_cache(forged, path, lod_path);
    try {
      (void)load_lod_file(lod_path, path);
      ADD_FAILURE() << c.name << ": accepted";
    } catch (const SceneCacheRejected& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(lod_path), std::string::npos) << what;
      EXPECT_NE(what.find(std::string(c.reason) + " of Gaussian " + std::to_string(merged + 5)), std::string::npos)
          << what;
    }
  }
  // The tree: an infinite box passes lo <= hi, so it is refused by name.
  GaussianModel forged = lod;
  forged.lod.back().lo[0] = -INFINITY;
  forged.lod.back().hi[0] = INFINITY;
  write_scene_cache(lod, path, lod_path);
  std::string bytes = read_file(lod_path);
  // The lod section is the file's last; its last node ends the file (sections are page-aligned,
  // so find the node by its bytes).
  const auto& node = lod.lod.back();
  const std::string needle(reinterpret_cast<const char*>(&node), sizeof node);
  const std::size_t at = bytes.rfind(needle);
  ASSERT_NE(at, std::string::npos);
  std::memcpy(&bytes[at], &forged.lod.back(), sizeof node);
  reseal_scene_cache(bytes, path);
  write_file(lod_path, bytes);
  try {
    (void)load_lod_file(lod_path, path);
    ADD_FAILURE() << "an infinite box was accepted";
  } catch (const SceneCacheRejected& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite box"), std::string::npos) << e.what();
  }
}

// Hostile models given straight to the CPU core (every 7th Gaussian of the bundled scene, SH
// degree 0, and of flowers_sh3, degree 3, where +-1e38 coefficients meet in one colour): each
// pipeline ends in a clear error or a finite image over a short orbit (an out-of-range tile range
// would be a sanitizer report in the fuzz build). The CUDA core's rows: tests/gpu (hostile).
TEST(HostileModels, CpuCoreDrawsFiniteImages) {
  std::vector<std::string> scenes{test::bundled_scene()};
  if (!test::data_file("scenes/flowers_sh3.ply").empty()) scenes.push_back(test::data_file("scenes/flowers_sh3.ply"));
  for (const std::string& scene : scenes) {
    const auto base = test::cached_scene(scene);
    const Bounds b = robust_bounds(*base);
    GeneratorParams g;
    g.width = 160;
    g.height = 120;
    g.duration_s = 0.05;  // 4 frames: a catgs key frame and its sub-frames
    g.rate_hz = 60.0;
    const Trace orbit = make_orbit(b, 1.5f * glm::length(b.extent()), 0.0f, 30.0f, g);
    for (const test::HostileCase& c : test::hostile_cases()) {
      auto m = std::make_shared<GaussianModel>(*base);
      test::apply_hostile(*m, c);
      for (Pipeline p : {Pipeline::vanilla, Pipeline::exact, Pipeline::catgs}) {
        RenderOptions o;
        o.pipeline = p;
        const auto r = make_renderer("cpu", m, o);
        Image img;
        std::size_t frames = 0, bad = 0;
        std::string error;
        for (const TimedCamera& t : orbit) {
          try {
            r->render(t.camera, img);
          } catch (const std::exception& e) {
            error = e.what();
            break;
          }
          ++frames;
          bad += test::count_non_finite(img.rgb);
        }
        const std::string what = m->name + ", " + c.name + ", " + pipeline_name(p);
        EXPECT_EQ(bad, 0u) << what << ": non-finite colour values over " << frames << " frames";
        EXPECT_TRUE(error.empty() || error.size() > 10) << what << ": " << error;
        if (!error.empty()) std::printf("%s: %s\n", what.c_str(), error.c_str());
      }
    }
  }
}

}  // namespace
}  // namespace catgs
