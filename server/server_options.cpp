#include "server_options.h"

#include "cpu_quota.h"
#include "process/scene_with_lod.h"
#include "speculation/settings.h"
#include "transport/origin_policy.h"
#include "transport/trusted_proxies.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <iostream>
#include <thread>
#include <stdexcept>

namespace catgs::server {

namespace {

int parse_int(const std::string& name, const std::string& v, int lo, int hi) {
  std::size_t used = 0;
  int x = 0;
  try {
    x = std::stoi(v, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument(name + " needs an integer, got '" + v + "'");
  }
  if (used != v.size()) throw std::invalid_argument(name + " needs an integer, got '" + v + "'");
  if (x < lo || x > hi)
    throw std::invalid_argument(name + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                                v);
  return x;
}

double parse_double(const std::string& name, const std::string& v, double lo, double hi) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(v, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument(name + " needs a number, got '" + v + "'");
  }
  if (used != v.size() || !(x >= lo && x <= hi))
    throw std::invalid_argument(name + " must be a number in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                                "], got '" + v + "'");
  return x;
}

// "WxH" with each side in [16, 4096] (the protocol's viewport range).
void parse_size(const std::string& name, const std::string& v, int& width, int& height) {
  const auto x = v.find('x');
  if (x == std::string::npos) throw std::invalid_argument(name + " needs WxH, got '" + v + "'");
  width = parse_int(name + " width", v.substr(0, x), 16, 4096);
  height = parse_int(name + " height", v.substr(x + 1), 16, 4096);
}

}  // namespace

std::string server_usage() {
  return "usage: catgs-server [options]\n"
         "  --scene FILE|DIR      scene file (default: assets/scenes/biker.compressed.ply), or a\n"
         "                        folder of them (.ply .spz .splat .glb .gltf .sog, SOG folders);\n"
         "                        repeat it to serve several: Hello.scene picks one by name (the file\n"
         "                        name without its extension), the first by default; GET /scenes\n"
         "                        lists them (--cameras applies to the first). The first loads at\n"
         "                        start-up, the others on first use (their sessions see progress)\n"
         "  --scene-memory-mb N   keep the loaded scenes' models within N MiB of host memory:\n"
         "                        a load unloads scenes no session uses, least recently used\n"
         "                        first (default 0: no budget, scenes stay once loaded)\n"
         "  --device-memory-mb N  device memory each GPU may hold of scenes and sessions' buffers,\n"
         "                        MiB (default 0: the GPU's memory less --device-memory-reserve-mb);\n"
         "                        a session is admitted only where its buffers fit, else refused\n"
         "                        with ERROR_SERVER_FULL and /readyz answers 503. With the CPU\n"
         "                        renderer: the allowance the same accounting uses (0: unlimited)\n"
         "  --device-memory-reserve-mb N  kept free on each GPU for the CUDA context, the encoders\n"
         "                        and the sort's scratch (default 2048)\n"
         "  --list-memory-mb N    a session's render-list buffers, MiB (default 512): a view whose\n"
         "                        list is longer is drawn in passes of tiles\n"
         "  --scene-cache off|read|write  each scene's cache (in --cache-dir, or beside it as\n"
         "                        SCENE.catgs-cache; `catgs-scene cache` writes one): read uses it when it is valid\n"
         "                        for the scene as it is now (else the scene is read, the reason\n"
         "                        logged); write also writes it after a plain load (a folder that\n"
         "                        is not writable is logged and ignored) (default read)\n"
         "  --lod off|read|write  level of detail: each scene is served from its LOD file (in the\n"
         "                        cache folder, else SCENE.catgs-lod beside it as `catgs-scene lod`\n"
         "                        writes it) when that is valid for the scene as it is now; else\n"
         "                        a scene of --lod-min-gaussians or more has its level of detail\n"
         "                        built at load (progress in the log and /metrics) and, with write,\n"
         "                        written to the cache folder (one that cannot be written is\n"
         "                        logged); off serves full detail (default write)\n"
         "  --cache-dir DIR|beside  where scene caches and LOD files are read first and written,\n"
         "                        named by each scene's content (default $XDG_CACHE_HOME/catgs or\n"
         "                        ~/.cache/catgs; beside: next to each scene); one found beside a\n"
         "                        scene is still read\n"
         "  --lod-min-gaussians N a scene of fewer Gaussians is served at full detail without\n"
         "                        building a level of detail (a LOD file for it is still used;\n"
         "                        default 2000000: the threshold's table: docs/history/level_of_detail.md)\n"
         "  --lod-error PX        the cut's screen-space error bound in pixels at 720 lines, scaled\n"
         "                        down with a smaller session's shorter side (0 = full detail;\n"
         "                        default 4, chosen against a supersampled render: RESULTS.md)\n"
         "  --splat-budget N|auto|off  the most Gaussians a frame's LOD cut may hold: over it the\n"
         "                        bound steps up (far detail merges first) and back down with\n"
         "                        hysteresis; auto sizes it per CUDA session from the GPU's\n"
         "                        measured throughput and the sessions sharing it (default auto)\n"
         "  --lod-max-error PX|off  the coarsest bound the splat budget may raise a frame to, px at\n"
         "                        720 lines (default 4, the --lod-error default: the budget never\n"
         "                        blurs that picture; what 5.66 costs: RESULTS.md);\n"
         "                        past it a GPU refuses the next visitor (server full)\n"
         "                        instead of blurring every view; off: up to 16x --lod-error\n"
         "  --splat-budget-share F  the share of a GPU's measured throughput (Gaussians a ms) the\n"
         "                        auto budget hands out to its sessions, in (0, 1] (default 0.4)\n"
         "  --occlusion-cull on|off  exact frames drop the list entries the session's last frame\n"
         "                        found behind its opaque pixels (default on)\n"
         "  --depth-grid PX|off   each frame carries the scene's depth at a vertex every PX\n"
         "                        pixels, one byte each, for the page's depth warp (default 32)\n"
         "  --cameras FILE        the scene's training cameras (INRIA cameras.json): the first view,\n"
         "                        orbit centre, up and speeds come from them (default: a\n"
         "                        cameras.json beside the scene or in its INRIA model folder, else\n"
         "                        the scene's dense content)\n"
         "  --port N              TCP port (default 8080; 0 = any free port)\n"
         "  --bind ADDR           listen address (default 0.0.0.0)\n"
         "  --renderer K          cpu | cuda | auto (default auto)\n"
         "  --gpus LIST           CUDA renderer: the GPUs sessions spread over, all or device\n"
         "                        numbers such as 0,1 (default all): one scene copy and 4 render\n"
         "                        lanes per GPU, each session on the GPU with the fewest sessions\n"
         "  --gpu-wait W          CUDA renderer: how a render lane waits for its frame: block (the\n"
         "                        default: asleep, the core goes to other work, e.g. x264) or spin\n"
         "                        (the driver's default with fewer GPUs than cores)\n"
         "  --encoder K           nvenc | x264 | auto (default auto: NVENC if usable, else x264)\n"
         "  --pipeline P          vanilla | exact | catgs (default exact)\n"
         "  --speculation LIST    catgs settings, e.g. window=2,backoff=0 (see below)\n"
         "  --web-root DIR        static files served at / (default: web_client/)\n"
         "  --max-sessions N      concurrent sessions (default 8)\n"
         "  --full-retry-ms N     reconnect hint sent with ERROR_SERVER_FULL: N .. 2N ms, drawn (default 2000)\n"
         "  --token-file FILE     access tokens, one a line: '[viewer|author|admin] TOKEN' (a bare TOKEN\n"
         "                        is admin). With tokens, Hello needs one and GET /metrics needs an\n"
         "                        admin one (Authorization: Bearer TOKEN); /healthz, /readyz stay open.\n"
         "                        The CATGS_TOKEN environment variable adds an admin token\n"
         "  --token T             an admin token on the command line (deprecated: every user of\n"
         "                        the host can read it in /proc; use --token-file or CATGS_TOKEN)\n"
         "  --allowed-origins LIST  origins besides the page's own and localhost whose pages may\n"
         "                        open a WebSocket, e.g. https://app.example,http://b.example:8080\n"
         "                        ('*': any). Upgrades without Origin (not a browser) are allowed\n"
         "  --hello-timeout-ms N  close a WebSocket that sends no Hello in N ms (default 10000)\n"
         "  --silent-timeout-ms N end a session that sends nothing for N ms (default 60000; the\n"
         "                        page pings every 2 s)\n"
         "  --scene-load-timeout-ms N  end a session whose scene has not loaded after N ms (default\n"
         "                        600000); the load goes on, and a later session may find it loaded\n"
         "  --max-connections-per-ip N  WebSocket connections from one address (default 128;\n"
         "                        0 = no cap; behind a proxy every client has the proxy's address)\n"
         "  --max-pre-hello N     connections that have not said Hello yet (default 256; 0 = no cap)\n"
         "  --trusted-proxies LIST  addresses / CIDR ranges of reverse proxies (an Ingress) whose\n"
         "                        X-Forwarded-For names the client for the per-address limits\n"
         "                        (default none: the header is ignored, clients can forge it)\n"
         "  --rate-limits LIST    name=RATE/BURST,... (per second / burst; see below)\n"
         "  --threads N           worker threads: sessions, encoding (default 0: the cores this\n"
         "                        process may use, its affinity and cgroup CPU limit, at least 4)\n"
         "  --render-lanes N      renders at once, sessions in turn (default: 4 per GPU with the\n"
         "                        CUDA renderer, --threads with the CPU one)\n"
         "  --frames-per-lane N   frames a render lane keeps on the GPU while it starts the next\n"
         "                        session's (default: 2 with the CUDA renderer, 1 with the CPU\n"
         "                        one; 1: each frame's planes before the next job; at most 16)\n"
         "  --slow-client-timeout-ms N  drop a client whose frames stay unread this long (10000)\n"
         "  --bitrate auto|off|KBPS  each stream's VBV maximum rate (capped CRF): auto (default)\n"
         "                        --bits-per-pixel x width x height x 60 frames/s, at least\n"
         "                        1500 kbit/s; off: --crf alone; a client's Quality lowers it\n"
         "  --bits-per-pixel auto|F  auto's bits per pixel per frame (default 0.09: 11.2 Mbit/s\n"
         "                        at 1080p60, 5.0 at 720p60; RESULTS.md \"Encoding\");\n"
         "                        auto: each scene and size from a probe of its own frames\n"
         "                        (0.02..0.096; RESULTS.md \"Encoding\")\n"
         "  --crf N               x264 quality floor, 0..51 (default 23): a simple view takes\n"
         "                        only the bits this quality needs\n"
         "  --vbv-ms N            the VBV's size in ms of the bitrate (default 100): how far one\n"
         "                        frame (an IDR) may exceed the average\n"
         "  --intra-refresh N     x264 periodic intra refresh over N frames instead of IDRs\n"
         "                        after the first (default 0: off)\n"
         "  --adaptive-quality on|off  lower a session's resolution (x0.75, x0.5) while the\n"
         "                        server skips its poses, climb back when frames would fit\n"
         "                        (default off; session/adaptive_quality.h has the rule)\n"
         "  --pose-prediction on|off  render each frame for where the visitor will be when it is\n"
         "                        shown (the client's motion, ahead by its reported pose-to-\n"
         "                        shown delay); the Frame says which pose (default on;\n"
         "                        session/pose_prediction.h)\n"
         "  --still-refine on|off  when the camera stops on a frame held back (smaller, or\n"
         "                        under a rate cap), draw its pose again at full size and the\n"
         "                        crf with no rate cap (default on; session/still_refine.h)\n"
         "  --encoder-threads N   sliced threads per session's encoder (default 0: auto, twice\n"
         "                        the usable cores shared by the live sessions, at least what\n"
         "                        the viewport needs for 60 frames/s, at most what it gains\n"
         "                        from: encode/encoder_policy.h)\n"
         "  --x264-preset P       x264 preset of the sessions' streams: auto (default:\n"
         "                        the slowest of ultrafast, ultrafast+cabac+deblock and\n"
         "                        superfast that half the cores afford at the live\n"
         "                        session count) or an x264 preset,\n"
         "                        with +cabac and +deblock to turn those tools back on\n"
         "                        (e.g. ultrafast+cabac+deblock)\n"
         "  --x264-floor P|off    the lowest step auto may take (ultrafast,\n"
         "                        ultrafast+cabac+deblock or superfast); a visitor whose\n"
         "                        stream half the cores could not encode at it is refused\n"
         "                        as full (default off: down to ultrafast, no such refusal)\n"
         "  --av1 auto|on|off     AV1 (libaom realtime) for clients that decode it: auto\n"
         "                        (default) while half the cores afford it at the live\n"
         "                        session count and the link does not limit the stream,\n"
         "                        on always, off never (H.264 only); x264 hosts only\n"
         "  --av1-speed N         libaom's realtime cpu-used for AV1 streams, 5..10 (default 10)\n"
         "  --max-frames-in-flight N    frames queued but unwritten per session (default 2)\n"
         "  --frame-deadline S|off  skip a rendered frame before encoding when it would reach\n"
         "                        the client more than S pose intervals after its pose and a\n"
         "                        newer pose waits (default 2: 33 ms at 60 poses/s)\n"
         "  --socket-send-buffer BYTES  SO_SNDBUF per WebSocket (default 524288; 0 = kernel)\n"
         "  --notsent-lowat BYTES  TCP_NOTSENT_LOWAT per WebSocket: bytes the kernel may hold\n"
         "                        unsent (default 1024; 0 = kernel): frames wait in the session,\n"
         "                        where the latest pose wins, not in the socket\n"
         "  --link-control on|off  the stream's bitrate follows the link: lowered when frames\n"
         "                        back up or the round trip grows, raised when they clear\n"
         "                        (default on; session/link_rate.h has the rule)\n"
         "  --max-viewport WxH    largest viewport a client may ask for (default 3840x2160; a\n"
         "                        viewport fits when its pixels are at most W x H and its longer\n"
         "                        side at most max(W, H)); larger Hello/Resize: INVALID_ARGUMENT\n"
         "  --max-pixels-in-flight N    pixels of all renders running at once, server-wide\n"
         "                        (default 0: two frames of --max-viewport); sessions take turns\n"
         "  --drain-timeout-s N   on SIGTERM, let live sessions stream up to N s before they get\n"
         "                        ERROR_SHUTTING_DOWN (default 30; /readyz answers 503 meanwhile,\n"
         "                        new sessions are refused); SIGINT or a second SIGTERM stops at once\n"
         "  --tls-cert FILE       TLS certificate, PEM (the server's first, then intermediates);\n"
         "                        with --tls-key the port serves only HTTPS and WSS (plain HTTP\n"
         "                        gets no answer). SIGHUP re-reads both files: new connections get\n"
         "                        the new certificate, open sessions go on; bad files are logged\n"
         "                        and the previous certificate stays\n"
         "  --tls-key FILE        the certificate's private key, PEM, unencrypted (both or neither)\n"
         "  --export-max-poses N  poses in an ExportVideoRequest (default 1800: one 64 KiB message)\n"
         "  --export-max-size WxH largest exported video (default 3840x2160; as --max-viewport)\n"
         "  --export-max-fps N    highest exported frame rate (default 60)\n"
         "  --export-max-seconds N  longest exported path, seconds (default 600)\n"
         "  --export-max-concurrent N  exports rendering at once, server-wide (default 1; 0: no\n"
         "                        exports); a session renders one at a time\n"
         "  --export-yield-ms N   an export frame waits up to N ms for a moment when no live\n"
         "                        render runs, then runs beside them (default 1000; 0: it waits\n"
         "                        only for queued live renders)\n"
         "  --export-dir DIR      folder of the exports' temporary MP4 files (default\n"
         "                        TMPDIR/catgs-exports; its catgs-export-*.mp4 files are deleted\n"
         "                        at start-up)\n"
         "  --probe URL           GET http[s]://HOST:PORT/PATH, exit 0 on 2xx, else 1 (a container\n"
         "                        HEALTHCHECK without curl or a shell; https does not check the\n"
         "                        certificate); starts no server\n"
         "rate limits (--rate-limits name=RATE/BURST,...; defaults shown):\n" +
         rate_limits_usage() + "catgs settings (--speculation name=value,...):\n" + speculation_settings_usage();
}

std::vector<std::string> scenes_in_folder(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(fs::path(dir) / "meta.json", ec)) return {(fs::path(dir) / "meta.json").string()};
  std::vector<std::string> found;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    const fs::path p = e.path();
    std::string ext = p.extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    std::error_code entry;  // a broken link is skipped, not a failed listing
    if (e.is_directory(entry)) {
      if (fs::exists(p / "meta.json", entry)) found.push_back((p / "meta.json").string());
    } else if (e.is_regular_file(entry) && (ext == ".ply" || ext == ".spz" || ext == ".splat" || ext == ".glb" ||
                                            ext == ".gltf" || ext == ".sog" || ext == ".catgs")) {
      found.push_back(p.string());
    }
  }
  if (ec) throw std::invalid_argument("--scene " + dir + ": cannot list the folder (" + ec.message() + ")");
  std::sort(found.begin(), found.end());
  if (found.empty())
    throw std::invalid_argument("--scene " + dir +
                                ": no scene files in the folder (.ply, .spz, .splat, .glb, .gltf, .sog, .catgs, or a "
                                "folder with a SOG meta.json)");
  return found;
}

bool parse_server_options(int argc, char** argv, ServerOptions& out) {
  out.scene = std::string(CATGS_SOURCE_DIR) + "/assets/scenes/biker.compressed.ply";
  out.web_root = std::string(CATGS_SOURCE_DIR) + "/web_client";
  bool scene_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::cout << server_usage();
      return false;
    }
    if (i + 1 >= argc) throw std::invalid_argument("option " + a + " needs a value");
    const std::string v = argv[++i];
    if (a == "--scene") {
      // The first --scene replaces the bundled default; later ones are further scenes. A folder
      // stands for the scenes in it (scenes_in_folder), in name order.
      std::error_code ec;
      const std::vector<std::string> files =
          std::filesystem::is_directory(v, ec) ? scenes_in_folder(v) : std::vector<std::string>{v};
      for (const std::string& file : files) {
        if (scene_given)
          out.more_scenes.push_back(file);
        else
          out.scene = file;
        scene_given = true;
      }
    } else if (a == "--cameras")
      out.cameras = v;
    else if (a == "--scene-cache") {
      if (v != "off" && v != "read" && v != "write")
        throw std::invalid_argument("--scene-cache must be off, read or write, got '" + v + "'");
      out.scene_cache = v;
    } else if (a == "--cache-dir") {
      if (v.empty()) throw std::invalid_argument("--cache-dir needs a folder (or beside)");
      out.cache_dir = v;
    } else if (a == "--lod-min-gaussians") {
      out.lod_min_gaussians = static_cast<std::uint64_t>(parse_double(a, v, 0.0, 1e12));
    } else if (a == "--lod") {
      (void)parse_lod_mode(v);  // refused here, with the option's name
      out.lod = v;
    } else if (a == "--lod-error")
      out.lod_error_px = static_cast<float>(parse_double(a, v, 0.0, 1e6));
    else if (a == "--splat-budget-share")
      out.splat_budget_share = parse_double(a, v, 0.01, 1.0);
    else if (a == "--lod-max-error")
      out.lod_max_error_px = v == "off" ? 0.0f : static_cast<float>(parse_double(a, v, 0.0, 1e6));
    else if (a == "--occlusion-cull") {
      if (v != "on" && v != "off") throw std::invalid_argument("--occlusion-cull must be on or off, got '" + v + "'");
      out.occlusion_cull = v == "on";
    } else if (a == "--depth-grid")
      out.depth_grid_px = v == "off" ? 0 : parse_int(a, v, 4, 512);
    else if (a == "--splat-budget") {
      out.auto_splat_budget = v == "auto";
      out.splat_budget = v == "auto" || v == "off" ? 0 : static_cast<std::uint64_t>(parse_double(a, v, 0.0, 1e12));
    } else if (a == "--scene-memory-mb")
      out.scene_memory_mb = parse_int(a, v, 0, 1 << 24);
    else if (a == "--device-memory-mb")
      out.device_memory_mb = parse_int(a, v, 0, 1 << 24);
    else if (a == "--device-memory-reserve-mb")
      out.device_memory_reserve_mb = parse_int(a, v, 0, 1 << 20);
    else if (a == "--list-memory-mb")
      out.list_memory_mb = parse_int(a, v, 16, 1 << 16);
    else if (a == "--port")
      out.port = parse_int(a, v, 0, 65535);
    else if (a == "--bind")
      out.bind = v;
    else if (a == "--renderer")
      out.renderer = v;
    else if (a == "--gpus")
      out.gpus = v;
    else if (a == "--gpu-wait") {
      if (v != "block" && v != "spin") throw std::invalid_argument("--gpu-wait: block or spin, got '" + v + "'");
      out.gpu_wait = v;
    } else if (a == "--encoder")
      out.encoder = v;
    else if (a == "--pipeline")
      out.pipeline = v;
    else if (a == "--speculation") {
      SpeculationParams check;
      apply_speculation_settings(check, v);  // refused here, before anything starts
      out.speculation = v;
    } else if (a == "--web-root")
      out.web_root = v;
    else if (a == "--max-sessions")
      out.max_sessions = parse_int(a, v, 1, 10000);
    else if (a == "--full-retry-ms")
      out.full_retry_ms = parse_int(a, v, 0, 3600000);
    else if (a == "--token")
      out.token = v;
    else if (a == "--token-file")
      out.token_file = v;
    else if (a == "--allowed-origins")
      out.allowed_origins = parse_origins(v);
    else if (a == "--hello-timeout-ms")
      out.hello_timeout_ms = parse_int(a, v, 100, 3600000);
    else if (a == "--silent-timeout-ms")
      out.silent_timeout_ms = parse_int(a, v, 100, 86400000);
    else if (a == "--scene-load-timeout-ms")
      out.scene_load_timeout_ms = parse_int(a, v, 100, 86400000);
    else if (a == "--max-connections-per-ip")
      out.max_connections_per_ip = parse_int(a, v, 0, 100000);
    else if (a == "--max-pre-hello")
      out.max_pre_hello = parse_int(a, v, 0, 100000);
    else if (a == "--trusted-proxies") {
      TrustedProxies::parse(v);  // refused here, before anything starts
      out.trusted_proxies = v;
    } else if (a == "--rate-limits")
      apply_rate_limits(out.rate_limits, v);
    else if (a == "--threads")
      out.threads = parse_int(a, v, 0, 256);
    else if (a == "--render-lanes")
      out.render_lanes = parse_int(a, v, 0, 256);
    else if (a == "--frames-per-lane")
      out.frames_per_lane = parse_int(a, v, 1, 16);
    else if (a == "--slow-client-timeout-ms")
      out.slow_client_timeout_ms = parse_int(a, v, 100, 3600000);
    else if (a == "--pose-prediction") {
      if (v != "on" && v != "off") throw std::invalid_argument("--pose-prediction: on or off, not '" + v + "'");
      out.pose_prediction = v == "on";
    } else if (a == "--adaptive-quality") {
      if (v != "on" && v != "off") throw std::invalid_argument("--adaptive-quality: on or off, not '" + v + "'");
      out.adaptive_quality = v == "on";
    } else if (a == "--crf")
      out.encoder_policy.crf = parse_int(a, v, 0, 51);
    else if (a == "--bitrate")
      out.encoder_policy.bitrate_kbps = v == "auto" ? -1 : v == "off" ? 0 : parse_int(a, v, 100, 1000000);
    else if (a == "--bits-per-pixel") {
      out.encoder_policy.content_rate = v == "auto";
      if (v != "auto") out.encoder_policy.bits_per_pixel = parse_double(a, v, 0.001, 10.0);
    } else if (a == "--vbv-ms")
      out.encoder_policy.vbv_buffer_ms = parse_int(a, v, 1, 10000);
    else if (a == "--intra-refresh")
      out.encoder_policy.intra_refresh_frames = parse_int(a, v, 0, 1000);
    else if (a == "--encoder-threads")
      out.encoder_policy.threads = parse_int(a, v, 0, 64);
    else if (a == "--x264-preset") {
      if (v != "auto" && !is_x264_preset(v))
        throw std::invalid_argument("--x264-preset: '" + v +
                                    "' is not auto or an x264 preset (ultrafast .. placebo, +cabac, +deblock)");
      out.encoder_policy.x264_preset = v;
    } else if (a == "--x264-floor") {
      try {
        out.encoder_policy.floor_step = ladder_step_named(v);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("--x264-floor: " + std::string(e.what()));
      }
    } else if (a == "--av1") {
      if (v != "auto" && v != "on" && v != "off")
        throw std::invalid_argument("--av1: auto, on or off, got '" + v + "'");
      out.encoder_policy.av1 = v;
    } else if (a == "--av1-speed")
      out.encoder_policy.av1_speed = parse_int(a, v, 5, 10);
    else if (a == "--frame-deadline")
      out.frame_deadline_slots = v == "off" ? 0.0 : parse_double(a, v, 0.0, 100.0);
    else if (a == "--max-frames-in-flight")
      out.max_frames_in_flight = parse_int(a, v, 1, 16);
    else if (a == "--socket-send-buffer")
      out.socket_send_buffer = parse_int(a, v, 0, 64 << 20);
    else if (a == "--notsent-lowat")
      out.notsent_lowat = parse_int(a, v, 0, 64 << 20);
    else if (a == "--still-refine") {
      if (v != "on" && v != "off") throw std::invalid_argument("--still-refine: on or off, not '" + v + "'");
      out.still_refine = v == "on";
    } else if (a == "--link-control") {
      if (v != "on" && v != "off") throw std::invalid_argument("--link-control: on or off, not '" + v + "'");
      out.link_control = v == "on";
    } else if (a == "--max-viewport")
      parse_size(a, v, out.max_viewport_width, out.max_viewport_height);
    else if (a == "--max-pixels-in-flight")
      out.max_pixels_in_flight = parse_int(a, v, 0, 1 << 30);
    else if (a == "--drain-timeout-s")
      out.drain_timeout_s = parse_int(a, v, 0, 3600);
    else if (a == "--tls-cert")
      out.tls_cert = v;
    else if (a == "--tls-key")
      out.tls_key = v;
    else if (a == "--export-max-poses")
      out.export_limits.max_poses = parse_int(a, v, 2, 1000000);
    else if (a == "--export-max-size")
      parse_size(a, v, out.export_limits.max_width, out.export_limits.max_height);
    else if (a == "--export-max-fps")
      out.export_limits.max_fps = parse_int(a, v, 1, 240);
    else if (a == "--export-max-seconds")
      out.export_limits.max_seconds = parse_int(a, v, 1, 86400);
    else if (a == "--export-max-concurrent")
      out.export_limits.max_concurrent = parse_int(a, v, 0, 64);
    else if (a == "--export-dir")
      out.export_dir = v;
    else if (a == "--export-yield-ms")
      out.export_yield_ms = parse_int(a, v, 0, 60000);
    else if (a == "--probe")
      out.probe_url = v;
    else
      throw std::invalid_argument("unknown option '" + a + "'\n" + server_usage());
  }
  // Encodes are CPU-bound: one worker per core this process may use (its affinity and its
  // cgroup's CPU limit, cpu_quota.h), not per core of the host; x264 adds its own threads.
  out.encoder_policy.usable_cores = usable_cores();
  if (out.threads == 0) out.threads = std::max(4, out.encoder_policy.usable_cores);
  if (out.max_pixels_in_flight == 0) out.max_pixels_in_flight = 2LL * out.max_viewport_width * out.max_viewport_height;
  if (out.tls_cert.empty() != out.tls_key.empty())
    throw std::invalid_argument("--tls-cert and --tls-key go together (one is missing)");
  if (out.renderer != "cpu" && out.renderer != "cuda" && out.renderer != "auto")
    throw std::invalid_argument("--renderer must be cpu, cuda or auto");
  if (out.encoder != "nvenc" && out.encoder != "x264" && out.encoder != "auto")
    throw std::invalid_argument("--encoder must be nvenc, x264 or auto");
  return true;
}

void resolve_access_tokens(ServerOptions& out, const char* env_token, std::ostream& warnings) {
  if (!out.token.empty()) {
    warnings << "catgs-server: warning: --token is visible to every user of this host (/proc/PID/cmdline); "
                "use --token-file FILE or the CATGS_TOKEN environment variable\n";
    out.tokens.add(out.token, Role::admin);
  }
  if (!out.token_file.empty()) out.tokens.add_file(out.token_file);
  if (env_token && *env_token) out.tokens.add(env_token, Role::admin);
}

SessionSettings session_settings(const ServerOptions& o) {
  SessionSettings s;
  s.max_sessions = o.max_sessions;
  s.full_retry_ms = o.full_retry_ms;
  s.hello_timeout_ms = o.hello_timeout_ms;
  s.silent_timeout_ms = o.silent_timeout_ms;
  s.scene_load_timeout_ms = o.scene_load_timeout_ms;
  s.slow_client_timeout_ms = o.slow_client_timeout_ms;
  s.max_viewport_width = o.max_viewport_width;
  s.max_viewport_height = o.max_viewport_height;
  s.rate_limits = o.rate_limits;
  s.tokens = o.tokens;
  s.export_limits = o.export_limits;
  s.frame.encoder = o.encoder;
  s.frame.encoder_policy = o.encoder_policy;
  s.frame.adaptive_quality = o.adaptive_quality;
  s.frame.pose_prediction = o.pose_prediction;
  s.frame.link_control = o.link_control;
  s.frame.still_refine = o.still_refine;
  s.frame.frame_deadline_slots = o.frame_deadline_slots;
  s.frame.max_frames_in_flight = o.max_frames_in_flight;
  s.frame.socket_send_buffer = o.socket_send_buffer;
  s.frame.lod.bound_px = o.lod_error_px;
  s.frame.lod.splat_budget = o.splat_budget;
  s.frame.lod.auto_budget = o.auto_splat_budget;
  s.frame.lod.max_bound_px = o.lod_max_error_px;
  s.frame.lod.budget_share = o.splat_budget_share;
  return s;
}

}  // namespace catgs::server
