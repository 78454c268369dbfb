// Command-line options of catgs-server.
#pragma once

#include <ostream>
#include <cstdint>
#include <string>
#include <vector>

#include "encode/encoder_policy.h"
#include "session/access_tokens.h"
#include "proto/message_validation.h"
#include "session/rate_limit.h"
#include "session/session_settings.h"

namespace catgs::server {

// Everything the server is configured with. Defaults match `catgs-server` with no arguments.
struct ServerOptions {
  std::string scene;                     // scene file (INRIA or compressed PLY): the first, the default
  std::vector<std::string> more_scenes;  // further --scene files (Hello.scene picks one by name)
  std::string cameras;                   // INRIA cameras.json of the scene's training views; "" = look beside it
  // --scene-memory-mb: host memory the loaded scenes' models may hold, MiB, before unused ones
  // are unloaded (process/scene_store.h); 0: no budget, every scene stays once loaded.
  int scene_memory_mb = 0;
  // Device memory (issue 61; gpu_assignment.h): --device-memory-mb bounds what each GPU may hold
  // of scene copies and sessions' buffers, MiB (0: the GPU's memory less
  // --device-memory-reserve-mb); with the CPU renderer it is the allowance the same accounting
  // admits sessions against (0: unlimited). --list-memory-mb bounds a session's render-list
  // buffers (RenderListBudget::max_bytes): a longer list is drawn in passes.
  int device_memory_mb = 0;
  int device_memory_reserve_mb = 2048;
  int list_memory_mb = 512;
  // --scene-cache: "off", "read" (a valid cache beside the scene is used) or "write" (also
  // written after a plain load); scene/scene_cache.h.
  std::string scene_cache = "read";
  // --lod: the level of detail of each scene (process/scene_with_lod.h): "off", "read" (the LOD
  // file beside the scene, else built in memory) or "write" (also written beside the scene).
  std::string lod = "write";
  // --cache-dir: where derived files (scene caches, LOD files) are read first and written, named
  // by the scene's content (scene/scene_cache.h derived_file_path): "" until resolved, then the
  // platform's cache folder ($XDG_CACHE_HOME/catgs or ~/.cache/catgs), a folder given, or
  // "beside" (next to each scene, the behaviour before issue 61).
  std::string cache_dir;
  // --lod-min-gaussians: a scene of fewer Gaussians gets no level of detail built (one with a LOD
  // file is still served from it).
  std::uint64_t lod_min_gaussians = 2000000;
  // --lod-error: the level-of-detail bound in pixels at 720 lines, scaled down with a smaller
  // session's shorter side (render/lod_bound.h; 0 = full detail). 4 px (issue 72): with the
  // fitted merges its picture against a 4x supersampled render is no worse than the 2 px cut
  // before them on the real paths and at 160x120, at about half the list entries (the table:
  // RESULTS.md, "Level of detail").
  float lod_error_px = 4.0f;
  // --splat-budget: Gaussians a frame's LOD cut may hold (render/lod_bound.h): N, 0 = none, or
  // "auto" (the default; CUDA sessions only), sized from the GPU's measured throughput.
  std::uint64_t splat_budget = 0;
  bool auto_splat_budget = true;
  // --lod-max-error: the coarsest bound the splat budget may raise a frame to (LodSettings::
  // max_bound_px; 0 = off, the ladder's top). Past it the door refuses the GPU's next visitor.
  // Default: the --lod-error default itself, the coarsest bound within 1 dB of the earlier 2 px
  // picture on the yardstick's three paths (the next step, 5.66 px, is not: RESULTS.md "Level of
  // detail"): the auto budget never blurs the default picture; where it would have to, the door
  // refuses instead.
  float lod_max_error_px = 4.0f;
  // --splat-budget-share: the share of a GPU's measured throughput the auto budget hands out.
  double splat_budget_share = 0.4;
  // --occlusion-cull on|off: exact frames drop the list entries that the session's last frame
  // found behind its opaque pixels (RenderOptions::occlusion_culling,
  // render_core/forward_model/occlusion.h; issue 72). Default on.
  bool occlusion_cull = true;
  // --depth-grid PX|off: exact frames carry their depth at a vertex every PX pixels
  // (Frame.depth_grid; RenderOptions::depth_grid_cell; issue 91). 0: none.
  int depth_grid_px = 32;
  int port = 8080;                 // TCP port; 0 lets the kernel pick (the chosen one is logged)
  std::string bind = "0.0.0.0";    // interface address to listen on
  std::string renderer = "auto";   // "cpu" | "cuda" | "auto"
  std::string gpus = "all";        // CUDA devices sessions spread over: "all" or "0,1" (gpu_assignment.h)
  std::string gpu_wait = "block";  // how render lanes wait for the GPU: "block" | "spin" (driver default)
  std::string encoder = "auto";    // "nvenc" | "x264" | "auto" (NVENC if it opens, else x264)
  std::string pipeline = "exact";  // "vanilla" | "exact" | "catgs"
  std::string speculation;         // catgs settings, "name=value,..." (speculation/settings.h)
  std::string web_root;            // folder served over HTTP at "/"
  int max_sessions = 8;            // sessions open at once; one more gets ERROR_SERVER_FULL
  int full_retry_ms = 2000;        // ERROR_SERVER_FULL's retry_after_ms: this .. 2x this (session.h kServerFullRetryMs)
  std::string token;               // --token T (visible in /proc: prefer the two below)
  std::string token_file;          // --token-file FILE: "[viewer|author|admin] TOKEN" lines
  // Every token from --token, --token-file and CATGS_TOKEN (resolve_access_tokens). When there is
  // one, Hello.token must be one of them and /metrics needs an admin token.
  AccessTokens tokens;
  // --allowed-origins: origins beside the page's own and localhost that may open a WebSocket.
  std::vector<std::string> allowed_origins;
  // Time limits for silence (issue 22): no Hello within this many ms after the WebSocket opened,
  // or no message at all from a session for this long, ends the connection with ERROR_TIMEOUT.
  int hello_timeout_ms = 10000;
  int silent_timeout_ms = 60000;
  // A session that waits longer than this for its scene to load (a stalled file system, a load
  // that hangs) ends with ERROR_TIMEOUT; the load itself goes on for later sessions (issue 20).
  int scene_load_timeout_ms = 600000;
  // WebSocket connections at once from one client address, and connections that have not said
  // Hello yet (0: no cap). Refused at the upgrade (429 / 503).
  int max_connections_per_ip = 128;
  int max_pre_hello = 256;
  // --trusted-proxies: reverse proxies whose X-Forwarded-For names the client for the
  // per-address caps and limits (empty: the TCP peer is the client).
  std::string trusted_proxies;
  RateLimitSettings rate_limits;       // --rate-limits
  int threads = 0;                     // Boost.Asio worker threads (strands, encoding); 0 = max(4, usable_cores())
  int render_lanes = 0;                // renders at once, sessions in rounds; 0 = 4 a GPU, `threads` for CPU
  int frames_per_lane = 0;             // --frames-per-lane: frames a lane keeps begun; 0 = 2 CUDA, 1 CPU
  int slow_client_timeout_ms = 10000;  // frames unwritten this long -> ERROR_TOO_SLOW
  bool adaptive_quality = false;       // --adaptive-quality (session/adaptive_quality.h)
  bool pose_prediction = true;         // --pose-prediction (session/pose_prediction.h)
  // --bitrate, --bits-per-pixel, --crf, --vbv-ms, --intra-refresh, --encoder-threads: how each
  // session's stream is sized (encode/encoder_policy.h); usable_cores is filled at parse time.
  EncoderPolicy encoder_policy;
  // --frame-deadline: a frame's display slot in pose intervals after its pose arrived; a rendered
  // frame that would miss it is skipped before encoding when a newer pose waits
  // (session/frame_pacing.h). 0: never skip.
  double frame_deadline_slots = 2.0;
  int max_frames_in_flight = 2;         // frames queued to the transport but not yet written
  int socket_send_buffer = 512 * 1024;  // SO_SNDBUF of WebSocket sockets, bytes (0 = kernel's)
  // TCP_NOTSENT_LOWAT of WebSocket sockets, bytes (0 = kernel's): the kernel's queue of bytes not
  // yet sent; a frame waits in the session until the one before has nearly left (link_rate.h).
  int notsent_lowat = 1024;
  bool link_control = true;        // --link-control: the bitrate follows the link (session/link_rate.h)
  bool still_refine = true;        // --still-refine: a still view ends sharp (session/still_refine.h)
  int max_viewport_width = 3840;   // --max-viewport WxH: larger Hello/Resize -> ERROR_INVALID_ARGUMENT
  int max_viewport_height = 2160;  //   (pixel count and longer side; message_validation.h)
  // Pixels of the renders running at once, server-wide (render_scheduler.h); 0 = two frames of
  // the largest viewport.
  long long max_pixels_in_flight = 0;
  // SIGTERM: seconds live sessions may keep streaming before they are told ERROR_SHUTTING_DOWN
  // (server.h "Drain"); 0 ends them at once.
  int drain_timeout_s = 30;
  // --tls-cert FILE --tls-key FILE (both or neither): the port serves HTTPS and WSS only
  // (transport/tls_setup.h); SIGHUP re-reads both files.
  std::string tls_cert;
  std::string tls_key;
  // Video export (session/video_export.h): caps on ExportVideoRequest (--export-max-poses,
  // --export-max-size WxH, --export-max-fps, --export-max-seconds, --export-max-concurrent) and
  // the folder of its temporary files (--export-dir; "" = TMPDIR/catgs-exports), emptied of
  // earlier exports' files at start-up.
  ExportLimits export_limits;
  std::string export_dir;
  // --export-yield-ms: how long an export frame waits for a moment when no live render runs
  // before it runs beside them (render/render_scheduler.h "Background jobs").
  int export_yield_ms = 1000;
  // --probe URL: GET the URL, exit 0 on a 2xx answer, 1 otherwise (probe.h), and do nothing else.
  std::string probe_url;
};

// Parses argv (`--name value` pairs, `--help`). Fills defaults for scene and web_root from the
// source directory compiled in. Throws std::invalid_argument with a message for bad input.
// Returns false when --help was given (usage already printed).
bool parse_server_options(int argc, char** argv, ServerOptions& out);

// The scenes a `--scene DIR` stands for: DIR/meta.json when DIR is an unbundled SOG scene, else
// its files named .ply (INRIA or compressed), .spz, .splat, .glb, .gltf or .sog and its
// sub-folders holding a SOG meta.json (as SUB/meta.json), not deeper, sorted by path. Throws
// std::invalid_argument naming the folder when it cannot be listed or holds no scene.
std::vector<std::string> scenes_in_folder(const std::string& dir);

// The part of `options` a session reads (session/session_settings.h).
SessionSettings session_settings(const ServerOptions& options);

// The usage text.
std::string server_usage();

// Gathers the access tokens into out.tokens: --token (with a warning on `warnings`: a command
// line is readable by every user of the host), --token-file, and `env_token` (CATGS_TOKEN; null
// or empty when unset). Throws std::invalid_argument for an unreadable or empty token file.
void resolve_access_tokens(ServerOptions& out, const char* env_token, std::ostream& warnings);

}  // namespace catgs::server
