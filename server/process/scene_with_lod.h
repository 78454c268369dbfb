// How the server reads a scene it serves: with its level of detail (issue 46; the cut is
// render_core/forward_model/lod.h, the build render_core/lod/lod_build.h).
//
// With LOD on (read or write, the default write), the LOD file beside the scene (SCENE.catgs-lod,
// scene/scene_cache.h: the leaves and the merged levels, keyed to the scene file as it is now)
// is served when it is valid. When it is missing, stale (the scene changed), foreign or refused
// by the checks every cache passes, the reason is logged, the scene is read (through its scene
// cache per `cache`), its level of detail built in this process (progress in the log and
// /metrics), and, in write mode, written beside the scene through a temporary file renamed into
// place (a folder that is not writable is logged and the built model served all the same). Off:
// the scene alone, every frame at full detail.
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
