// Command-line options of catgs-server: one declaration per option (server_options.cpp's option
// table, CLI11) gives the parser, --help and the default --help shows. The parser writes straight
// into the nested settings each part of the server reads, so nothing is copied from one struct to
// another and a struct built without options (as tests and the fuzz target build them) holds the
// defaults a server started without options runs.
#pragma once

#include <cstdint>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "session/session_settings.h"
#include "transport/transport.h"

namespace catgs::server {

// Where the scenes come from and what derived files are kept of them (process/scene_store.h,
// process/scene_with_lod.h, scene/scene_cache.h).
struct StoreOptions {
  std::string scene;                     // the first scene file, the default (Hello.scene picks by name)
  std::vector<std::string> more_scenes;  // further --scene files
  std::string cameras;                   // INRIA cameras.json of the first scene; "" = look beside it
  // Host memory the loaded scenes' models may hold, MiB, before unused ones are unloaded; 0: no
  // budget, every scene stays once loaded.
  int scene_memory_mb = 0;
  std::string scene_cache = "read";  // "off" | "read" | "write" (scene/scene_cache.h)
  std::string lod = "write";         // "off" | "read" | "write" (process/scene_with_lod.h)
  // Where derived files (scene caches, LOD files) are read first and written, named by the
  // scene's content: "" = the platform's cache folder ($XDG_CACHE_HOME/catgs or ~/.cache/catgs),
  // a folder, or "beside" (next to each scene, the behaviour before issue 61).
  std::string cache_dir;
  // A scene of fewer Gaussians gets no level of detail built (one with a LOD file still uses it).
  std::uint64_t lod_min_gaussians = 2000000;
};

// The renderer, its GPUs and the render lanes (render/, renderer/).
struct RenderSettings {
  std::string renderer = "auto";   // "cpu" | "cuda" | "auto"
  std::string gpus = "all";        // CUDA devices sessions spread over: "all" or "0,1" (gpu_assignment.h)
  std::string gpu_wait = "block";  // how render lanes wait for the GPU: "block" | "spin" (driver default)
  std::string pipeline = "exact";  // "vanilla" | "exact" | "catgs"
  std::string speculation;         // catgs settings, "name=value,..." (speculation/settings.h)
  // Device memory each GPU may hold of scene copies and sessions' buffers, MiB (0: the GPU's
  // memory less device_memory_reserve_mb; with the CPU renderer the allowance the same
  // accounting admits sessions against, 0: unlimited). gpu_assignment.h.
  int device_memory_mb = 0;
  int device_memory_reserve_mb = 2048;
  int list_memory_mb = 512;  // a session's render-list buffers (RenderListBudget::max_bytes), MiB
  // Exact frames drop the list entries the session's last frame found behind its opaque pixels
  // (RenderOptions::occlusion_culling; issue 72).
  bool occlusion_cull = true;
  // Exact frames carry their depth at a vertex every this many pixels (Frame.depth_grid;
  // RenderOptions::depth_grid_cell; issue 91); 0: none.
  int depth_grid_px = 32;
  int render_lanes = 0;     // renders at once, sessions in rounds; 0 = 4 a GPU, `threads` for CPU
  int frames_per_lane = 0;  // frames a lane keeps begun; 0 = 2 CUDA, 1 CPU
  // Pixels of the renders running at once, server-wide (render_scheduler.h); 0 = two frames of
  // the largest viewport.
  long long max_pixels_in_flight = 0;
  // How long an export frame waits for a moment when no live render runs before it runs beside
  // them, ms (render/render_scheduler.h "Background jobs").
  int export_yield_ms = 1000;
};

// Everything the server is configured with. Defaults (the member initializers, here and in the
// nested structs) are `catgs-server` with no arguments, except scene and web root, which
// parse_server_options fills from the source folder compiled in.
struct ServerOptions {
  StoreOptions store;
  RenderSettings render;
  TransportOptions transport;
  SessionSettings session;  // what each session reads (session/session_settings.h)
  int threads = 0;          // Boost.Asio worker threads (strands, encoding); 0 = max(4, usable_cores())
  // SIGTERM: seconds live sessions may keep streaming before they are told ERROR_SHUTTING_DOWN
  // (server.h "Drain"); 0 ends them at once.
  int drain_timeout_s = 30;
  std::string token;       // --token T (visible in /proc: prefer the two below)
  std::string token_file;  // --token-file FILE: "[viewer|author|admin] TOKEN" lines
  std::string export_dir;  // video exports' temporary files; "" = TMPDIR/catgs-exports
  std::string probe_url;   // --probe URL: GET it, exit 0 on a 2xx answer, 1 otherwise (probe.h)
};

// Parses argv (`--name value` or `--name=value`, `--help`). Fills defaults for scene and web root
// from the source directory compiled in. Throws std::invalid_argument with a message naming the
// option for bad input. Returns false when --help was given (usage already printed).
bool parse_server_options(int argc, char** argv, ServerOptions& out);

// The usage text (--help): each option with its value's name, what it does and its default.
std::string server_usage();

// Each option's value in `options`, written as the option takes it (e.g. "--lod-error" -> "4",
// "--splat-budget" -> "auto"): the text --help shows as the default for ServerOptions{}. Options
// without a value to show (--scene, --token, --probe, ...) are left out.
std::map<std::string, std::string> option_values(const ServerOptions& options);

// The scenes a `--scene DIR` stands for: DIR/meta.json when DIR is an unbundled SOG scene, else
// its files named .ply (INRIA or compressed), .spz, .splat, .glb, .gltf or .sog and its
// sub-folders holding a SOG meta.json (as SUB/meta.json), not deeper, sorted by path. Throws
// std::invalid_argument naming the folder when it cannot be listed or holds no scene.
std::vector<std::string> scenes_in_folder(const std::string& dir);

// Gathers the access tokens into out.session.tokens: --token (with a warning on `warnings`: a
// command line is readable by every user of the host), --token-file, and `env_token`
// (CATGS_TOKEN; null or empty when unset). Throws std::invalid_argument for an unreadable or
// empty token file.
void resolve_access_tokens(ServerOptions& out, const char* env_token, std::ostream& warnings);

}  // namespace catgs::server
