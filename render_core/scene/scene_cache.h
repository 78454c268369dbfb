// The scene cache (issue 37): a scene once read, stored beside it in the layout the render cores
// use, so the next load is a memory-mapped copy at disk speed instead of a parse.
//
// What it holds: the GaussianModel's arrays exactly as load_scene returns them (float32, in file
// order, which is the chunk order both cores cull by), and what DeviceScene::upload derives from
// them: the SH in binary16 (forward_model/sh_storage.h half_bits) and the bound of every chunk of
// fm::kChunkSize Gaussians (forward_model/chunk_bounds.h). A cached load gives the same model, bit
// for bit, as a plain one (tests/unit/scene_cache_test.cpp).
//
// It is derived data, never trusted beyond what it can prove:
// - the source: its size, modification time (ns) and an XXH3 hash of its first 64 KiB (a PLY's
//   header) are stored; any difference rejects the cache;
// - the version: kSceneCacheVersion, bumped whenever a reader's output or this layout changes; a
//   cache of another version (or a file that is not a cache) is rejected;
// - the bytes: the header carries its own XXH3 hash and every 4 MiB block of every section its
//   own, checked as the block is copied out; a truncated file fails its size check.
// - the values: XXH3 detects damage, not forgery (anyone can compute it), so a cache, and a LOD
//   file's merged levels, are held to the scene readers' own check: a value a reader refuses (not
//   finite, GaussianModel::validate) rejects the cache, checked as its block is copied out, and
//   the LOD tree must pass fm::validate_lod (issue 49).
// The sh_half and chunks sections are checked by hash only, not against the model: no renderer
// reads them (DeviceScene derives both from the model); one that uploads them must prove them
// first.
// A rejected cache is rebuilt by load_scene_cached (SceneCacheMode::write), with a log line that
// says why.
//
// File layout (little endian; offsets from the file's start):
//   0      CacheHeader (below), 4096 bytes reserved
//   4096   the block hashes: uint64 XXH3-64 of each kCacheBlockBytes block of each section, the
//          sections in order
//   then   the sections, each at a 4096-byte boundary: means [N, 3] f32, log_scales [N, 3] f32,
//          rotations [N, 4] f32 (w, x, y, z), opacity_logits [N] f32, sh [N, K, 3] f32,
//          sh_half [N, K, 3] binary16 bits, chunks [chunk_count(N)] fm::ChunkBounds (32 bytes),
//          lod [chunk_count(N) or 0] fm::LodNode (32 bytes; forward_model/lod.h)
//   (units and frames those of GaussianModel, gaussian_model.h).
//
// A LOD file (catgs-scene lod, conventionally S.catgs-lod) is such a cache of the LOD model
// lod/lod_build.h makes from scene S, keyed to S: its N holds the leaves and the
// merged levels, its lod section the tree. It is our own derived file, not a PLY: another
// viewer would draw every level on top of the others.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

#include "forward_model/chunk_bounds.h"
#include "scene/gaussian_model.h"
#include "scene/load_progress.h"
#include "scene/ply_io.h"

namespace catgs {

// Bump when a scene reader's output, the chunk bounds, the half rounding or this layout change.
inline constexpr uint32_t kSceneCacheVersion = 2;  // 2: the lod section
inline constexpr uint64_t kCacheBlockBytes = 4ull << 20;

// The cache file of a scene: the scene's path + ".catgs-cache" (a SOG's meta.json gets
// meta.json.catgs-cache in its folder).
std::string scene_cache_path(const std::string& scene_path);

// Where a file derived from a scene (its cache, ".catgs-cache"; its LOD file, ".catgs-lod") goes
// in `folder` (issue 61: derived files in a cache folder, not beside the user's scene): the
// scene's file name, a 16-hex-digit XXH3 of its size and first 64 KiB (the content, so two
// scenes of one name in different folders never share a file, and a moved scene finds its own),
// then `suffix`. An empty folder: beside the scene (scene_path + suffix). The file's own key
// (size, modification time, head hash) still decides whether it is valid. A scene that cannot
// be read is named by a hash of its path instead (its load then fails on its own terms).
std::string derived_file_path(const std::string& scene_path, const std::string& suffix, const std::string& folder);

// The folder derived files go to by default: $XDG_CACHE_HOME/catgs, else $HOME/.cache/catgs
// (the XDG base directory convention), else empty (beside the scene).
std::string default_cache_folder();

// What a derived file records of its source (a cache, a LOD file): its size, modification time
// (ns) and an XXH3-64 of its first 64 KiB (its header, for a PLY). Throws SceneFileError naming
// `path` when it cannot be read.
struct SourceStamp {
  uint64_t size = 0;
  int64_t mtime_ns = 0;
  uint64_t head_hash = 0;
};
SourceStamp source_stamp(const std::string& path);

// Thrown when a cache cannot be used; what() names the cache file and says why (missing,
// truncated, not a cache, another version, written for a different or changed source, a
// checksum mismatch, a value a scene loader refuses, a bad LOD tree).
class SceneCacheRejected : public std::runtime_error {
 public:
  SceneCacheRejected(const std::string& cache_path, const std::string& why)
      : std::runtime_error(cache_path + ": " + why) {}
};

// Writes the cache of `model` (as load_scene returned it for `scene_path`) to `cache_path`
// through a temporary file beside it renamed into place, so a reader never maps half a cache.
// `threads` as LoadOptions::threads. Memory: the sections are written block by block from the
// model (SH rounded to half a block at a time), so writing adds a few blocks per thread. Throws
// SceneFileError naming the file (scene_path cannot be read, cache_path's folder is not
// writable, the disk is full).
void write_scene_cache(const GaussianModel& model, const std::string& scene_path, const std::string& cache_path,
                       int threads = 0);

// An opened cache file: mapped read-only, its header checked against the source.
class SceneCache {
 public:
  // Throws SceneCacheRejected naming cache_path (see above for why).
  static std::unique_ptr<SceneCache> open(const std::string& cache_path, const std::string& scene_path);
  ~SceneCache();

  uint64_t size() const;  // Gaussians
  int sh_degree() const;
  bool has_lod() const;  // the model has a level of detail (a LOD file)
  // Checks every block's hash and copies the model out (the sections' pages leave this process's
  // memory behind the copy, so the load peaks near the model's size); name = scene_name(scene).
  // Every value must be one a scene loader accepts (finite) and the LOD tree valid. The half SH
  // and chunk sections are hash-checked too. `progress` as load_scene's, on the calling
  // thread. Throws SceneCacheRejected on a mismatch.
  GaussianModel read_model(int threads = 0, const LoadProgress& progress = {}) const;
  // The upload layout, straight from the mapping (hash-checked by read_model, not against the model):
  const uint16_t* sh_half() const;        // [N, K, 3] binary16 bits (fm::half_bits of sh)
  const fm::ChunkBounds* chunks() const;  // [fm::chunk_count(N)]

  struct Impl;

 private:
  explicit SceneCache(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Forges a cache as an attacker with write access to a scene's folder could: recomputes, in the
// cache file image `bytes`, the source stamp (from `scene_path`), every block hash, the hash
// table's hash and the header hash from the header's own layout fields, whatever they say (a
// block or table that would lie outside `bytes` is skipped; `bytes` shorter than a header is left
// as it is). For the tests and the fuzz target (tests/fuzz/fuzz_scene_cache.cpp), so they reach
// the checks behind the hashes. Throws SceneFileError when scene_path cannot be read.
void reseal_scene_cache(std::string& bytes, const std::string& scene_path);

enum class SceneCacheMode {
  off,    // load_scene, nothing else
  read,   // a valid cache is used; otherwise the scene is read (the reason logged)
  write,  // as read, and a missing or rejected cache is written after the scene is read (a folder
          // that is not writable is logged and the load goes on)
};

struct CachedLoadOptions {
  LoadOptions load;  // threads, for the parse and the cache copy
  SceneCacheMode mode = SceneCacheMode::write;
  std::string cache_path;                       // empty: scene_cache_path(path)
  std::function<void(const std::string&)> log;  // one line per decision (used, rejected, written)
};

// What load_scene_cached did.
struct CachedLoadReport {
  bool from_cache = false;
  bool written = false;  // the cache was (re)written
  std::string why;       // why the cache was not used (empty when it was, or mode off)
};

// A LOD file of scene `scene_path`, in either form: a compact scene keyed to it (compact_file.h
// read_compact_lod, what catgs-scene lod and the server write) or a cache as above. The LOD
// model, lod filled and validated. Throws
// SceneCacheRejected naming lod_path (missing, truncated, foreign, of another version or
// source, a checksum mismatch, a bad tree, or a plain cache without LOD).
GaussianModel load_lod_file(const std::string& lod_path, const std::string& scene_path, int threads = 0,
                            const LoadProgress& progress = {});

// load_scene through the cache. Throws what load_scene throws (the cache's own faults never
// fail a load: they are logged and the scene is read).
GaussianModel load_scene_cached(const std::string& path, const CachedLoadOptions& options,
                                const LoadProgress& progress = {}, CachedLoadReport* report = nullptr);

}  // namespace catgs
