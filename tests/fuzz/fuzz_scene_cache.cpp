// Fuzz target: any bytes as a scene cache or LOD file (scene/scene_cache.h), or as a compact
// scene (scene/compact_file.h, bytes that start with its magic), resealed first as a forger would
// (reseal_scene_cache: the source stamp, every block hash, the table's and the header's hash
// recomputed from the mutated header's own fields; reseal_compact_scene the same), so mutations
// of the header fields and of the sections reach the checks behind the hashes (issues 49, 74).
// Then:
// - SceneCache::open and read_model, and load_lod_file for a file with a LOD section; or
//   read_compact_scene;
// - a model that comes out must pass GaussianModel::validate (what every scene reader calls);
// - a small one (at most 4096 Gaussians) is drawn at 16 x 16 by the CPU core (exact, the LOD cut
//   at 1 px), and every colour value must be finite.
// SceneCacheRejected or SceneFileError (and the render budget's std::length_error) is the expected
// answer; a crash,
// a sanitizer report, another exception or a failed check (abort) is a finding.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>
#include <algorithm>

#include "render_small.h"
#include "scene/compact_file.h"
#include "scene/scene_cache.h"

namespace {

// This process's files: a cache and the scene it claims to be derived from (any bytes: the
// stamp is its size, time and first bytes' hash).
std::string scratch_base() { return "/tmp/catgs-fuzz-cache-" + std::to_string(::getpid()); }
const std::string& scene_path() {
  static const std::string path = scratch_base() + ".scene";
  return path;
}
const std::string& cache_path() {
  static const std::string path = scratch_base() + ".catgs-cache";
  return path;
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (!bytes.empty() && std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) std::abort();
  std::fclose(f);
}

void check(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_scene_cache: %s\n", what);
  std::abort();
}

// A model a file gave: it must pass validate; a small one is drawn with finite colours.
void check_model(const std::shared_ptr<const catgs::GaussianModel>& model) {
  try {
    model->validate();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_scene_cache: a model that validate refuses: %s\n", e.what());
    std::abort();
  }
  if (model->size() > 0 && model->size() <= 4096) {
    catgs::RenderOptions options;
    options.pipeline = catgs::Pipeline::exact;
    options.lod_error_px = 1.0f;
    catgs::Image image;
    if (catgs::fuzz::render_small(model, options, image))
      for (float v : image.rgb) check(std::isfinite(v), "a non-finite colour value in the render");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const bool scene_written = (write_bytes(scene_path(), "a scene's bytes"), true);
  (void)scene_written;
  std::string bytes(reinterpret_cast<const char*>(data), size);
  if (catgs::looks_like_compact(std::vector<uint8_t>(bytes.begin(), bytes.begin() + std::min<size_t>(8, size)))) {
    catgs::reseal_compact_scene(bytes);
    write_bytes(cache_path(), bytes);
    try {
      check_model(std::make_shared<const catgs::GaussianModel>(catgs::read_compact_scene(cache_path(), {}, 1)));
    } catch (const catgs::SceneFileError&) {
      // The reader's answer to bytes it cannot trust: a clear reason naming the file.
    } catch (const std::length_error&) {}
    return 0;
  }
  catgs::reseal_scene_cache(bytes, scene_path());
  write_bytes(cache_path(), bytes);
  try {
    const auto cache = catgs::SceneCache::open(cache_path(), scene_path());
    auto model = std::make_shared<const catgs::GaussianModel>(cache->read_model(1));
    check(model->lod.empty() != cache->has_lod(), "has_lod disagrees with the model");
    if (cache->has_lod())
      check(catgs::load_lod_file(cache_path(), scene_path(), 1).size() == model->size(),
            "load_lod_file and read_model disagree");
    check_model(model);
  } catch (const catgs::SceneCacheRejected&) {
    // The cache's answer to bytes it cannot trust: a clear reason naming the file.
  } catch (const std::length_error&) {
    // The render budget's answer to a scene whose render list would not fit (renderer.h).
  }
  return 0;
}
