// How the server reads a scene it serves: with its level of detail (issue 46; the cut is
// render_core/forward_model/lod.h, the build render_core/lod/lod_build.h).
//
// With LOD on (read or write, the default write), the scene's LOD file (scene/scene_cache.h: the
// leaves and the merged levels, keyed to the scene file as it is now) is served when it is
// valid: the one in the cache folder (derived_file_path), else SCENE.catgs-lod beside the scene.
// When there is none, or it is stale (the scene changed), foreign or refused by the checks every
// cache passes, the reason is logged and the scene is read (through its scene cache per `cache`,
// found the same way); a scene of at least `min_gaussians` then has its level of detail built in
// this process (progress in the log and /metrics) and, in write mode, written to the cache
// folder through a temporary file renamed into place (a folder that cannot be made or written
// is logged and the built model served all the same); a smaller one is served as it is. Off: the
// scene alone, every frame at full detail.
#pragma once

#include <functional>
#include <string>

#include "process/server_metrics.h"
#include "scene/gaussian_model.h"
#include "scene/load_progress.h"
#include "scene/scene_cache.h"

namespace catgs::server {

enum class LodMode { off, read, write };

// "off", "read" or "write"; throws std::invalid_argument naming the option otherwise.
LodMode parse_lod_mode(const std::string& text);

struct SceneWithLodOptions {
  SceneCacheMode cache = SceneCacheMode::read;
  LodMode lod = LodMode::write;
  // Where derived files are read first and written (scene/scene_cache.h derived_file_path; the
  // server's --cache-dir); empty: beside the scene. A LOD file or scene cache beside the scene
  // (as `catgs-scene lod` and `cache` write them) is read when the folder holds none.
  std::string cache_dir;
  // A scene of fewer Gaussians is served without a level of detail unless a LOD file for it
  // exists (the cut saves a small scene's frames little and its build costs every first start:
  // docs/history/level_of_detail.md "Where a level of detail pays", the threshold's table).
  std::uint64_t min_gaussians = 0;
  std::function<void(const std::string&)> log;  // one line per decision and progress step
  ServerMetrics* metrics = nullptr;             // LOD builds and their progress (may be null)
};

// The model to serve for scene file `path`. `progress` as SceneStore's loader: (done, total),
// rising; where a LOD is built, the read counts for the first half and the build the second.
// Throws what load_scene throws for the scene itself (a LOD or cache file's faults only decide
// what is rebuilt; they never fail a load).
GaussianModel load_scene_with_lod(const std::string& path, const SceneWithLodOptions& options,
                                  const LoadProgress& progress);

}  // namespace catgs::server
