#include "process/scene_with_lod.h"

#include <chrono>
#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "lod/lod_build.h"
#include "scene/compact_file.h"
#include "scene/format_detect.h"
#include "scene/scene_peek.h"

namespace catgs::server {

LodMode parse_lod_mode(const std::string& text) {
  if (text == "off") return LodMode::off;
  if (text == "read") return LodMode::read;
  if (text == "write") return LodMode::write;
  throw std::invalid_argument("--lod must be off, read or write, got '" + text + "'");
}

namespace {

void say(const SceneWithLodOptions& o, const std::string& line) {
  if (o.log) o.log(line);
}

// Builds the level of detail of `scene` (read from `path`), reporting into the second half of
// `progress`, the log (every quarter) and the metrics.
GaussianModel build_for(const std::string& path, const GaussianModel& scene, const SceneWithLodOptions& o,
                        const LoadProgress& progress) {
  ServerMetrics* m = o.metrics;
  if (m) m->lod_builds_running++;
  int quarter = 0;
  LodBuildOptions b;
  // A compressed PLY keeps its chunks as the leaves, so the LOD file keeps its codes.
  try {
    b.keep_order = peek_scene(path).format == "compressed_ply";
  } catch (const std::exception&) {
    b.keep_order = false;  // read already: a file that will not peek is not a compressed PLY
  }
  b.progress = [&](uint64_t done, uint64_t total) {
    if (m && total) m->lod_build_permille = static_cast<std::int64_t>(done * 1000 / total);
    if (total && done * 4 / total > static_cast<uint64_t>(quarter) && done < total) {
      quarter = static_cast<int>(done * 4 / total);
      say(o, "scene " + path + ": building its level of detail: " + std::to_string(quarter * 25) + "%");
    }
    if (progress) progress(total + done, 2 * total);
  };
  LodBuildReport report;
  try {
    GaussianModel lod = build_lod(scene, b, &report);
    if (m) {
      m->lod_builds_running--;
      m->lod_builds_total++;
    }
    std::ostringstream line;
    line << "scene " << path << ": level of detail built in " << static_cast<long>(report.seconds * 1000) << " ms ("
         << scene.size() << " Gaussians + " << lod.size() - lod_leaf_gaussians(lod) << " merged, " << lod.lod.size()
         << " chunks in " << report.level_nodes.size() << " levels)";
    say(o, line.str());
    return lod;
  } catch (...) {
    if (m) m->lod_builds_running--;
    throw;
  }
}

// The derived file to read for `path`: the cache folder's when it exists, else the one beside the
// scene when that exists, else the cache folder's (where it will be written).
std::string derived_to_read(const std::string& path, const std::string& suffix, const std::string& folder) {
  const std::string in_folder = derived_file_path(path, suffix, folder);
  std::error_code ec;
  if (folder.empty() || std::filesystem::exists(in_folder, ec)) return in_folder;
  return std::filesystem::exists(path + suffix, ec) ? path + suffix : in_folder;
}

// Makes `file`'s folder (a cache folder may not exist yet); false, with the reason logged, when
// it cannot be made.
bool make_folder_of(const std::string& file, const SceneWithLodOptions& o) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(file).parent_path(), ec);
  if (ec) say(o, "cache folder " + std::filesystem::path(file).parent_path().string() + ": " + ec.message());
  return !ec;
}

}  // namespace

GaussianModel load_scene_with_lod(const std::string& path, const SceneWithLodOptions& o, const LoadProgress& progress) {
  // A compact scene is read as it is (no scene cache: it reads faster than one), with the level of
  // detail it carries.
  const bool compact = detect_scene_format(path) == SceneFormat::compact;
  CachedLoadOptions c;
  c.mode = compact ? SceneCacheMode::off : o.cache;
  c.log = o.log;
  // A cache found beside the scene is read there; one written goes to the cache folder (so in
  // --scene-cache write mode a cache beside the scene is passed over for the folder's: nothing
  // is ever written beside the user's scene).
  c.cache_path = derived_to_read(path, ".catgs-cache", o.cache_dir);
  if (c.mode == SceneCacheMode::write && c.cache_path == path + ".catgs-cache" && !o.cache_dir.empty())
    c.cache_path = derived_file_path(path, ".catgs-cache", o.cache_dir);
  if (c.mode == SceneCacheMode::write && !make_folder_of(c.cache_path, o)) c.mode = SceneCacheMode::read;
  if (o.lod == LodMode::off) {
    GaussianModel m = load_scene_cached(path, c, progress);
    if (!m.lod.empty()) say(o, "scene " + path + ": served at full detail (--lod off), its merged levels left out");
    if (!m.lod.empty()) m = lod_leaves(std::move(m));
    return m;
  }

  const std::string lod_path = derived_to_read(path, ".catgs-lod", o.cache_dir);
  if (!compact) try {
      const auto t0 = std::chrono::steady_clock::now();
      GaussianModel m = load_lod_file(lod_path, path, 0, progress);
      const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0);
      say(o, "scene " + path + ": level of detail from " + lod_path + " (" + std::to_string(m.size()) + " Gaussians, " +
                 std::to_string(m.lod.size()) + " chunks) in " + std::to_string(ms.count()) + " ms");
      return m;
    } catch (const SceneCacheRejected& e) {
      say(o, "scene " + path + ": LOD file not used (" + e.what() + ")");
    }
  // The read is the first half of the progress, the build the second.
  const LoadProgress half = [&progress](uint64_t done, uint64_t total) {
    if (progress) progress(done, 2 * total);
  };
  GaussianModel scene = load_scene_cached(path, c, half);
  if (!scene.lod.empty()) {
    say(o, "scene " + path + ": level of detail from the compact scene (" + std::to_string(scene.size()) +
               " Gaussians, " + std::to_string(scene.lod.size()) + " chunks)");
    if (progress) progress(1, 1);
    return scene;
  }
  if (scene.size() < o.min_gaussians) {
    say(o, "scene " + path + ": served without a level of detail (" + std::to_string(scene.size()) +
               " Gaussians, under --lod-min-gaussians " + std::to_string(o.min_gaussians) + ")");
    if (progress) progress(1, 1);
    return scene;
  }
  GaussianModel lod = build_for(path, scene, o, progress);
  // Written to the cache folder (never over a file beside the scene that was refused) as a
  // compact scene keyed to the source; served quantized as the file will give it from the next
  // start on, so every start draws the same picture.
  const std::string lod_out = derived_file_path(path, ".catgs-lod", o.cache_dir);
  if (o.lod == LodMode::write && make_folder_of(lod_out, o)) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      quantize_compact(lod);
      write_compact_scene(lod, lod_out, path);
      if (o.metrics) o.metrics->lod_files_written_total++;
      const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0);
      say(o, "scene " + path + ": LOD file written to " + lod_out + " in " + std::to_string(ms.count()) + " ms");
    } catch (const std::exception& e) {
      say(o, "scene " + path + ": LOD file not written (" + std::string(e.what()) + "); serving the built one");
    }
  }
  return lod;
}

}  // namespace catgs::server
