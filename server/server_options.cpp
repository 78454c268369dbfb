#include "server_options.h"

#include <CLI/CLI.hpp>

#include "cpu_quota.h"
#include "process/scene_with_lod.h"
#include "speculation/settings.h"
#include "transport/origin_policy.h"
#include "transport/trusted_proxies.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <functional>
#include <iostream>
#include <sstream>
#include <stdexcept>

namespace catgs::server {

namespace {

long long parse_integer(const std::string& name, const std::string& v, long long lo, long long hi) {
  std::size_t used = 0;
  long long x = 0;
  try {
    x = std::stoll(v, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument(name + " needs an integer, got '" + v + "'");
  }
  if (used != v.size()) throw std::invalid_argument(name + " needs an integer, got '" + v + "'");
  if (x < lo || x > hi)
    throw std::invalid_argument(name + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                                v);
  return x;
}

double parse_number(const std::string& name, const std::string& v, double lo, double hi) {
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

std::string number_text(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

// "WxH" with each side in [16, 4096] (the protocol's viewport range).
void parse_size(const std::string& name, const std::string& v, int& width, int& height) {
  const auto x = v.find('x');
  if (x == std::string::npos) throw std::invalid_argument(name + " needs WxH, got '" + v + "'");
  width = static_cast<int>(parse_integer(name + " width", v.substr(0, x), 16, 4096));
  height = static_cast<int>(parse_integer(name + " height", v.substr(x + 1), 16, 4096));
}

// Words wrapped to `width` columns ('\n' kept): CLI11 indents each line under the option.
std::string wrap(const std::string& text, std::size_t width) {
  std::string out, line;
  std::istringstream paragraphs(text);
  std::string paragraph;
  bool first_paragraph = true;
  while (std::getline(paragraphs, paragraph)) {
    if (!first_paragraph) out += "\n";
    first_paragraph = false;
    std::istringstream words(paragraph);
    std::string word;
    line.clear();
    while (words >> word) {
      if (!line.empty() && line.size() + 1 + word.size() > width) {
        out += line + "\n";
        line.clear();
      }
      line += (line.empty() ? "" : " ") + word;
    }
    out += line;
  }
  return out;
}

constexpr std::size_t kNameColumn = 32;  // --help: option names, then what they do
constexpr std::size_t kHelpWidth = 66;

// How an option's value is read into its field and written back as text: the text --help shows
// as its default and option_values() returns. `get` empty: no value to show (a file, a list).
struct Field {
  std::function<void(const std::string&)> set;
  std::function<std::string()> get;
};

Field integer(std::string name, int& field, int lo, int hi) {
  return {[&field, name, lo, hi](const std::string& v) { field = static_cast<int>(parse_integer(name, v, lo, hi)); },
          [&field] { return std::to_string(field); }};
}
Field integer(std::string name, long long& field, long long lo, long long hi) {
  return {[&field, name, lo, hi](const std::string& v) { field = parse_integer(name, v, lo, hi); },
          [&field] { return std::to_string(field); }};
}
// A count given as an integer or in scientific notation (2e6).
Field count(std::string name, std::uint64_t& field) {
  return {[&field, name](const std::string& v) { field = static_cast<std::uint64_t>(parse_number(name, v, 0, 1e12)); },
          [&field] { return std::to_string(field); }};
}
// An integer where `off` is 0.
Field integer_or_off(std::string name, int& field, int lo, int hi) {
  return {[&field, name, lo, hi](const std::string& v) {
            field = v == "off" ? 0 : static_cast<int>(parse_integer(name, v, lo, hi));
          },
          [&field] { return field == 0 ? std::string("off") : std::to_string(field); }};
}
template <class T>
Field number(std::string name, T& field, double lo, double hi) {
  return {[&field, name, lo, hi](const std::string& v) { field = static_cast<T>(parse_number(name, v, lo, hi)); },
          [&field] { return number_text(field); }};
}
// A number where `off` is 0.
template <class T>
Field number_or_off(std::string name, T& field, double lo, double hi) {
  return {[&field, name, lo, hi](const std::string& v) {
            field = v == "off" ? T(0) : static_cast<T>(parse_number(name, v, lo, hi));
          },
          [&field] { return field == T(0) ? std::string("off") : number_text(field); }};
}
Field on_off(std::string name, bool& field) {
  return {[&field, name](const std::string& v) {
            if (v != "on" && v != "off") throw std::invalid_argument(name + " must be on or off, got '" + v + "'");
            field = v == "on";
          },
          [&field] { return std::string(field ? "on" : "off"); }};
}
// One of `words`.
Field word(std::string name, std::string& field, std::vector<std::string> words) {
  return {[&field, name, words](const std::string& v) {
            if (std::find(words.begin(), words.end(), v) == words.end()) {
              std::string list;
              for (const std::string& w : words) list += (list.empty() ? "" : ", ") + w;
              throw std::invalid_argument(name + " must be one of " + list + ", got '" + v + "'");
            }
            field = v;
          },
          [&field] { return field; }};
}
// Any text, shown as the default when `shown`.
Field text(std::string& field, bool shown = true) {
  Field f{[&field](const std::string& v) { field = v; }, {}};
  if (shown) f.get = [&field] { return field; };
  return f;
}
Field size(std::string name, int& width, int& height) {
  return {[&width, &height, name](const std::string& v) { parse_size(name, v, width, height); },
          [&width, &height] { return std::to_string(width) + "x" + std::to_string(height); }};
}

// The option table: every option of catgs-server, declared once, bound to one ServerOptions.
class OptionTable {
 public:
  explicit OptionTable(ServerOptions& o);

  CLI::App& app() { return app_; }
  std::map<std::string, std::string> values() const {
    std::map<std::string, std::string> out;
    for (const auto& [name, get] : getters_) out[name] = get();
    return out;
  }

 private:
  // `help` says what the option does; its default is appended from the field (or `shown_default`
  // where the field holds none to show).
  CLI::Option* add(const std::string& name, const std::string& value_name, const std::string& help, Field field,
                   const std::string& shown_default = "") {
    const std::string def = field.get ? field.get() : shown_default;
    const std::string described = def.empty() ? help : help + " (default " + def + ")";
    CLI::Option* opt = app_.add_option_function<std::string>(name, field.set, wrap(described, kHelpWidth));
    opt->type_name(value_name)->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    if (field.get) getters_.emplace_back(name, field.get);
    return opt;
  }
  // An option that may be given again, each value applied in order.
  void add_each(const std::string& name, const std::string& value_name, const std::string& help,
                std::function<void(const std::string&)> apply) {
    app_.add_option_function<std::vector<std::string>>(
            name,
            [apply](const std::vector<std::string>& values) {
              for (const std::string& v : values) apply(v);
            },
            wrap(help, kHelpWidth))
        ->type_name(value_name)
        ->allow_extra_args(false);
  }
  void declare_store(StoreOptions& s);
  void declare_render(RenderSettings& r);
  void declare_transport(TransportOptions& t, FrameSettings& f);
  void declare_session(SessionSettings& s);
  void declare_frame(FrameSettings& f);
  void declare_encoder(EncoderPolicy& e);
  void declare_process(ServerOptions& o);

  CLI::App app_{"catgs-server: streams Gaussian-splat scenes rendered on this host to browsers (docs/DESIGN.md)",
                "catgs-server"};
  std::vector<std::pair<std::string, std::function<std::string()>>> getters_;
  bool scene_given_ = false;
};

OptionTable::OptionTable(ServerOptions& o) {
  app_.get_formatter()->column_width(kNameColumn);
  app_.footer("rate limits (--rate-limits name=RATE/BURST,...; defaults shown):\n" + rate_limits_usage() +
              "catgs settings (--speculation name=value,...):\n" + speculation_settings_usage());
  declare_store(o.store);
  declare_render(o.render);
  declare_transport(o.transport, o.session.frame);
  declare_session(o.session);
  declare_frame(o.session.frame);
  declare_encoder(o.session.frame.encoder_policy);
  declare_process(o);
}

void OptionTable::declare_store(StoreOptions& s) {
  // The first --scene replaces the bundled default; later ones are further scenes. A folder stands
  // for the scenes in it (scenes_in_folder), in name order.
  add_each("--scene", "FILE|DIR",
           "scene file, or a folder of them (.ply .spz .splat .glb .gltf .sog .catgs, SOG folders); repeat it to "
           "serve several: Hello.scene picks one by name (the file name without its extension), the first by "
           "default; GET /scenes lists them (--cameras applies to the first). The first loads at start-up, the "
           "others on first use (their sessions see progress) (default assets/scenes/biker.compressed.ply)",
           [&s, this](const std::string& v) {
             std::error_code ec;
             const std::vector<std::string> files =
                 std::filesystem::is_directory(v, ec) ? scenes_in_folder(v) : std::vector<std::string>{v};
             for (const std::string& file : files) {
               if (scene_given_)
                 s.more_scenes.push_back(file);
               else
                 s.scene = file;
               scene_given_ = true;
             }
           });
  add("--cameras", "FILE",
      "the scene's training cameras (INRIA cameras.json): the first view, orbit centre, up and speeds come from "
      "them (default: a cameras.json beside the scene or in its INRIA model folder, else the scene's dense content)",
      text(s.cameras, false));
  add("--scene-memory-mb", "N",
      "keep the loaded scenes' models within N MiB of host memory: a load unloads scenes no session uses, least "
      "recently used first (0: no budget, scenes stay once loaded)",
      integer("--scene-memory-mb", s.scene_memory_mb, 0, 1 << 24));
  add("--scene-cache", "off|read|write",
      "each scene's cache (in --cache-dir, or beside it as SCENE.catgs-cache; `catgs-scene cache` writes one): "
      "read uses it when it is valid for the scene as it is now (else the scene is read, the reason logged); "
      "write also writes it after a plain load (a folder that is not writable is logged and ignored)",
      word("--scene-cache", s.scene_cache, {"off", "read", "write"}));
  add("--lod", "off|read|write",
      "level of detail: each scene is served from its LOD file (in the cache folder, else SCENE.catgs-lod beside "
      "it as `catgs-scene lod` writes it) when that is valid for the scene as it is now; else a scene of "
      "--lod-min-gaussians or more has its level of detail built at load (progress in the log and /metrics) and, "
      "with write, written to the cache folder (one that cannot be written is logged); off serves full detail",
      word("--lod", s.lod, {"off", "read", "write"}));
  add("--cache-dir", "DIR|beside",
      "where scene caches and LOD files are read first and written, named by each scene's content (beside: next "
      "to each scene); one found beside a scene is still read (default $XDG_CACHE_HOME/catgs or ~/.cache/catgs)",
      {[&s](const std::string& v) {
         if (v.empty()) throw std::invalid_argument("--cache-dir needs a folder (or beside)");
         s.cache_dir = v;
       },
       {}});
  add("--lod-min-gaussians", "N",
      "a scene of fewer Gaussians is served at full detail without building a level of detail (a LOD file for it "
      "is still used; the threshold's table: docs/history/level_of_detail.md)",
      count("--lod-min-gaussians", s.lod_min_gaussians));
}

void OptionTable::declare_render(RenderSettings& r) {
  add("--renderer", "cpu|cuda|auto", "the render core", word("--renderer", r.renderer, {"cpu", "cuda", "auto"}));
  add("--gpus", "LIST",
      "CUDA renderer: the GPUs sessions spread over, all or device numbers such as 0,1: one scene copy and 4 "
      "render lanes per GPU, each session on the GPU with the fewest sessions",
      text(r.gpus));
  add("--gpu-wait", "block|spin",
      "CUDA renderer: how a render lane waits for its frame: block (asleep, the core goes to other work, e.g. "
      "x264) or spin (the driver's default with fewer GPUs than cores)",
      word("--gpu-wait", r.gpu_wait, {"block", "spin"}));
  add("--pipeline", "vanilla|exact|catgs", "the render pipeline",
      word("--pipeline", r.pipeline, {"vanilla", "exact", "catgs"}));
  add("--speculation", "LIST", "catgs settings, e.g. window=2,backoff=0 (see below)",
      {[&r](const std::string& v) {
         SpeculationParams check;
         apply_speculation_settings(check, v);  // refused here, before anything starts
         r.speculation = v;
       },
       {}});
  add("--device-memory-mb", "N",
      "device memory each GPU may hold of scenes and sessions' buffers, MiB (0: the GPU's memory less "
      "--device-memory-reserve-mb); a session is admitted only where its buffers fit, else refused with "
      "ERROR_SERVER_FULL and /readyz answers 503. With the CPU renderer: the allowance the same accounting uses "
      "(0: unlimited)",
      integer("--device-memory-mb", r.device_memory_mb, 0, 1 << 24));
  add("--device-memory-reserve-mb", "N",
      "kept free on each GPU for the CUDA context, the encoders and the sort's scratch, MiB",
      integer("--device-memory-reserve-mb", r.device_memory_reserve_mb, 0, 1 << 20));
  add("--list-memory-mb", "N",
      "a session's render-list buffers, MiB: a view whose list is longer is drawn in passes of tiles",
      integer("--list-memory-mb", r.list_memory_mb, 16, 1 << 16));
  add("--occlusion-cull", "on|off",
      "exact frames drop the list entries the session's last frame found behind its opaque pixels",
      on_off("--occlusion-cull", r.occlusion_cull));
  add("--depth-grid", "PX|off",
      "each frame carries the scene's depth at a vertex every PX pixels, one byte each, for the page's depth warp",
      integer_or_off("--depth-grid", r.depth_grid_px, 4, 512));
  add("--render-lanes", "N",
      "renders at once, sessions in turn (0: 4 per GPU with the CUDA renderer, --threads with the CPU one)",
      integer("--render-lanes", r.render_lanes, 0, 256));
  add("--frames-per-lane", "N",
      "frames a render lane keeps on the GPU while it starts the next session's (0: 2 with the CUDA renderer, 1 "
      "with the CPU one; 1: each frame's planes before the next job)",
      integer("--frames-per-lane", r.frames_per_lane, 0, 16));
  add("--max-pixels-in-flight", "N",
      "pixels of all renders running at once, server-wide (0: two frames of --max-viewport); sessions take turns",
      integer("--max-pixels-in-flight", r.max_pixels_in_flight, 0, 1 << 30));
  add("--export-yield-ms", "N",
      "an export frame waits up to N ms for a moment when no live render runs, then runs beside them (0: it "
      "waits only for queued live renders)",
      integer("--export-yield-ms", r.export_yield_ms, 0, 60000));
}

void OptionTable::declare_transport(TransportOptions& t, FrameSettings& f) {
  add("--port", "N", "TCP port (0: any free port)", integer("--port", t.port, 0, 65535));
  add("--bind", "ADDR", "listen address", text(t.bind));
  add("--web-root", "DIR", "static files served at / (default: web_client/ of the source tree)",
      text(t.web_root, false));
  // The transport sets it on each socket as it opens; the session then sizes it by the link
  // (session_stream.cpp) up to this.
  t.socket_send_buffer = f.socket_send_buffer;
  add("--socket-send-buffer", "BYTES",
      "SO_SNDBUF per WebSocket, the most the session sizes it to by the link (0: "
      "the kernel's)",
      {[&t, &f](const std::string& v) {
         t.socket_send_buffer = f.socket_send_buffer =
             static_cast<int>(parse_integer("--socket-send-buffer", v, 0, 64 << 20));
       },
       [&f] { return std::to_string(f.socket_send_buffer); }});
  add("--notsent-lowat", "BYTES",
      "TCP_NOTSENT_LOWAT per WebSocket: bytes the kernel may hold unsent (0: the kernel's): frames wait in the "
      "session, where the latest pose wins, not in the socket",
      integer("--notsent-lowat", t.notsent_lowat, 0, 64 << 20));
  add("--allowed-origins", "LIST",
      "origins besides the page's own and localhost whose pages may open a WebSocket, e.g. "
      "https://app.example,http://b.example:8080 ('*': any). Upgrades without Origin (not a browser) are allowed",
      {[&t](const std::string& v) { t.origins = OriginPolicy(parse_origins(v)); }, {}});
  add("--max-connections-per-ip", "N",
      "WebSocket connections from one address (0: no cap; behind a proxy every client has the proxy's address)",
      integer("--max-connections-per-ip", t.max_per_ip, 0, 100000));
  add("--max-pre-hello", "N", "connections that have not said Hello yet (0: no cap)",
      integer("--max-pre-hello", t.max_pre_hello, 0, 100000));
  add("--trusted-proxies", "LIST",
      "addresses / CIDR ranges of reverse proxies (an Ingress) whose X-Forwarded-For names the client for the "
      "per-address limits (default none: the header is ignored, clients can forge it)",
      {[&t](const std::string& v) { t.proxies = TrustedProxies::parse(v); }, {}});
  add("--tls-cert", "FILE",
      "TLS certificate, PEM (the server's first, then intermediates); with --tls-key the port serves only HTTPS "
      "and WSS (plain HTTP gets no answer). SIGHUP re-reads both files: new connections get the new certificate, "
      "open sessions go on; bad files are logged and the previous certificate stays",
      text(t.tls_cert, false));
  add("--tls-key", "FILE", "the certificate's private key, PEM, unencrypted (both or neither)", text(t.tls_key, false));
}

void OptionTable::declare_session(SessionSettings& s) {
  add("--max-sessions", "N", "concurrent sessions", integer("--max-sessions", s.max_sessions, 1, 10000));
  add("--full-retry-ms", "N", "reconnect hint sent with ERROR_SERVER_FULL: N .. 2N ms, drawn",
      integer("--full-retry-ms", s.full_retry_ms, 0, 3600000));
  add("--hello-timeout-ms", "N", "close a WebSocket that sends no Hello in N ms",
      integer("--hello-timeout-ms", s.hello_timeout_ms, 100, 3600000));
  add("--silent-timeout-ms", "N", "end a session that sends nothing for N ms (the page pings every 2 s)",
      integer("--silent-timeout-ms", s.silent_timeout_ms, 100, 86400000));
  add("--scene-load-timeout-ms", "N",
      "end a session whose scene has not loaded after N ms; the load goes on, and a later session may find it "
      "loaded",
      integer("--scene-load-timeout-ms", s.scene_load_timeout_ms, 100, 86400000));
  add("--slow-client-timeout-ms", "N", "drop a client whose frames stay unread this long",
      integer("--slow-client-timeout-ms", s.slow_client_timeout_ms, 100, 3600000));
  add("--max-viewport", "WxH",
      "largest viewport a client may ask for (a viewport fits when its pixels are at most W x H and its longer "
      "side at most max(W, H)); larger Hello/Resize: INVALID_ARGUMENT",
      size("--max-viewport", s.max_viewport_width, s.max_viewport_height));
  add_each("--rate-limits", "LIST", "name=RATE/BURST,... (per second / burst; see below)",
           [&s](const std::string& v) { apply_rate_limits(s.rate_limits, v); });
  ExportLimits& e = s.export_limits;
  add("--export-max-poses", "N", "poses in an ExportVideoRequest (one 64 KiB message holds 1800)",
      integer("--export-max-poses", e.max_poses, 2, 1000000));
  add("--export-max-size", "WxH", "largest exported video (as --max-viewport)",
      size("--export-max-size", e.max_width, e.max_height));
  add("--export-max-fps", "N", "highest exported frame rate", integer("--export-max-fps", e.max_fps, 1, 240));
  add("--export-max-seconds", "N", "longest exported path, seconds",
      integer("--export-max-seconds", e.max_seconds, 1, 86400));
  add("--export-max-concurrent", "N",
      "exports rendering at once, server-wide (0: no exports); a session renders one at a time",
      integer("--export-max-concurrent", e.max_concurrent, 0, 64));
}

void OptionTable::declare_frame(FrameSettings& f) {
  add("--encoder", "nvenc|x264|auto", "the video encoder (auto: NVENC if usable, else x264)",
      word("--encoder", f.encoder, {"nvenc", "x264", "auto"}));
  LodSettings& l = f.lod;
  add("--lod-error", "PX",
      "the cut's screen-space error bound in pixels at 720 lines, scaled down with a smaller session's shorter "
      "side (0: full detail; the default chosen against a supersampled render: RESULTS.md)",
      number("--lod-error", l.bound_px, 0.0, 1e6));
  add("--splat-budget", "N|auto|off",
      "the most Gaussians a frame's LOD cut may hold: over it the bound steps up (far detail merges first) and "
      "back down with hysteresis; auto sizes it per CUDA session from the GPU's measured throughput and the "
      "sessions sharing it",
      {[&l](const std::string& v) {
         l.auto_budget = v == "auto";
         l.splat_budget =
             v == "auto" || v == "off" ? 0 : static_cast<std::uint64_t>(parse_number("--splat-budget", v, 0, 1e12));
       },
       [&l] { return l.auto_budget    ? std::string("auto")
                     : l.splat_budget ? std::to_string(l.splat_budget)
                                      : "off"; }});
  add("--lod-max-error", "PX|off",
      "the coarsest bound the splat budget may raise a frame to, px at 720 lines (the default, the --lod-error "
      "default: the budget never blurs that picture; what 5.66 costs: RESULTS.md); past it a GPU refuses the "
      "next visitor (server full) instead of blurring every view; off: up to 16x --lod-error",
      number_or_off("--lod-max-error", l.max_bound_px, 0.0, 1e6));
  add("--splat-budget-share", "F",
      "the share of a GPU's measured throughput (Gaussians a ms) the auto budget hands out to its sessions, in "
      "(0, 1]",
      number("--splat-budget-share", l.budget_share, 0.01, 1.0));
  add("--adaptive-quality", "on|off",
      "lower a session's resolution (x0.75, x0.5) while the server skips its poses, climb back when frames would "
      "fit (session/adaptive_quality.h has the rule)",
      on_off("--adaptive-quality", f.adaptive_quality));
  add("--pose-prediction", "on|off",
      "render each frame for where the visitor will be when it is shown (the client's motion, ahead by its "
      "reported pose-to-shown delay); the Frame says which pose (session/pose_prediction.h)",
      on_off("--pose-prediction", f.pose_prediction));
  add("--still-refine", "on|off",
      "when the camera stops on a frame held back (smaller, or under a rate cap), draw its pose again at full "
      "size and the crf with no rate cap (session/still_refine.h)",
      on_off("--still-refine", f.still_refine));
  add("--link-control", "on|off",
      "the stream's bitrate follows the link: lowered when frames back up or the round trip grows, raised when "
      "they clear (session/link_rate.h has the rule)",
      on_off("--link-control", f.link_control));
  add("--frame-deadline", "S|off",
      "skip a rendered frame before encoding when it would reach the client more than S pose intervals after its "
      "pose and a newer pose waits (2: 33 ms at 60 poses/s)",
      number_or_off("--frame-deadline", f.frame_deadline_slots, 0.0, 100.0));
  add("--max-frames-in-flight", "N", "frames queued but unwritten per session",
      integer("--max-frames-in-flight", f.max_frames_in_flight, 1, 16));
}

void OptionTable::declare_encoder(EncoderPolicy& e) {
  add("--bitrate", "auto|off|KBPS",
      "each stream's VBV maximum rate (capped CRF): auto: --bits-per-pixel x width x height x 60 frames/s, at "
      "least 1500 kbit/s; off: --crf alone; a client's Quality lowers it",
      {[&e](const std::string& v) {
         e.bitrate_kbps = v == "auto"  ? -1
                          : v == "off" ? 0
                                       : static_cast<int>(parse_integer("--bitrate", v, 100, 1000000));
       },
       [&e] {
         return e.bitrate_kbps < 0 ? std::string("auto") : e.bitrate_kbps == 0 ? "off" : std::to_string(e.bitrate_kbps);
       }});
  add("--bits-per-pixel", "auto|F",
      "auto's bits per pixel per frame (0.09: 11.2 Mbit/s at 1080p60, 5.0 at 720p60; RESULTS.md \"Encoding\"); "
      "auto: each scene and size from a probe of its own frames (0.02..0.096)",
      {[&e](const std::string& v) {
         e.content_rate = v == "auto";
         if (v != "auto") e.bits_per_pixel = parse_number("--bits-per-pixel", v, 0.001, 10.0);
       },
       [&e] { return e.content_rate ? std::string("auto") : number_text(e.bits_per_pixel); }});
  add("--crf", "N", "x264 quality floor, 0..51: a simple view takes only the bits this quality needs",
      integer("--crf", e.crf, 0, 51));
  add("--vbv-ms", "N", "the VBV's size in ms of the bitrate: how far one frame (an IDR) may exceed the average",
      integer("--vbv-ms", e.vbv_buffer_ms, 1, 10000));
  add("--intra-refresh", "N", "x264 periodic intra refresh over N frames instead of IDRs after the first (0: off)",
      integer("--intra-refresh", e.intra_refresh_frames, 0, 1000));
  add("--encoder-threads", "N",
      "sliced threads per session's encoder (0: auto, twice the usable cores shared by the live sessions, at "
      "least what the viewport needs for 60 frames/s, at most what it gains from: encode/encoder_policy.h)",
      integer("--encoder-threads", e.threads, 0, 64));
  add("--x264-preset", "P",
      "x264 preset of the sessions' streams: auto (the slowest of ultrafast, ultrafast+cabac+deblock and "
      "superfast that half the cores afford at the live session count) or an x264 preset, with +cabac and "
      "+deblock to turn those tools back on (e.g. ultrafast+cabac+deblock)",
      {[&e](const std::string& v) {
         if (v != "auto" && !is_x264_preset(v))
           throw std::invalid_argument("--x264-preset: '" + v +
                                       "' is not auto or an x264 preset (ultrafast .. placebo, +cabac, +deblock)");
         e.x264_preset = v;
       },
       [&e] { return e.x264_preset; }});
  add("--x264-floor", "P|off",
      "the lowest step auto may take (ultrafast, ultrafast+cabac+deblock or superfast); a visitor whose stream "
      "half the cores could not encode at it is refused as full (off: down to ultrafast, no such refusal)",
      {[&e](const std::string& v) {
         try {
           e.floor_step = ladder_step_named(v);
         } catch (const std::invalid_argument& error) {
           throw std::invalid_argument("--x264-floor: " + std::string(error.what()));
         }
       },
       [&e] { return e.floor_step < 0 ? std::string("off") : std::string(kPresetLadder[e.floor_step].name); }});
  add("--av1", "auto|on|off",
      "AV1 (libaom realtime) for clients that decode it: auto while half the cores afford it at the live session "
      "count and the link does not limit the stream, on always, off never (H.264 only); x264 hosts only",
      word("--av1", e.av1, {"auto", "on", "off"}));
  add("--av1-speed", "N", "libaom's realtime cpu-used for AV1 streams, 5..10",
      integer("--av1-speed", e.av1_speed, 5, 10));
}

void OptionTable::declare_process(ServerOptions& o) {
  add("--threads", "N",
      "worker threads: sessions, encoding (0: the cores this process may use, its affinity and cgroup CPU limit, "
      "at least 4)",
      integer("--threads", o.threads, 0, 256));
  add("--drain-timeout-s", "N",
      "on SIGTERM, let live sessions stream up to N s before they get ERROR_SHUTTING_DOWN (/readyz answers 503 "
      "meanwhile, new sessions are refused); SIGINT or a second SIGTERM stops at once",
      integer("--drain-timeout-s", o.drain_timeout_s, 0, 3600));
  add("--token-file", "FILE",
      "access tokens, one a line: '[viewer|author|admin] TOKEN' (a bare TOKEN is admin). With tokens, Hello needs "
      "one and GET /metrics needs an admin one (Authorization: Bearer TOKEN); /healthz, /readyz stay open. The "
      "CATGS_TOKEN environment variable adds an admin token",
      text(o.token_file, false));
  add("--token", "T",
      "an admin token on the command line (deprecated: every user of the host can read it in /proc; use "
      "--token-file or CATGS_TOKEN)",
      text(o.token, false));
  add("--export-dir", "DIR",
      "folder of the exports' temporary MP4 files, whose catgs-export-*.mp4 files are deleted at start-up",
      text(o.export_dir, false), "TMPDIR/catgs-exports");
  add("--probe", "URL",
      "GET http[s]://HOST:PORT/PATH, exit 0 on 2xx, else 1 (a container HEALTHCHECK without curl or a shell; "
      "https does not check the certificate); starts no server",
      text(o.probe_url, false));
}

// The defaults no member initializer can hold: files of the source tree compiled in.
void fill_source_defaults(ServerOptions& o) {
  o.store.scene = std::string(CATGS_SOURCE_DIR) + "/assets/scenes/biker.compressed.ply";
  o.transport.web_root = std::string(CATGS_SOURCE_DIR) + "/web_client";
}

}  // namespace

std::string server_usage() {
  ServerOptions defaults;
  fill_source_defaults(defaults);
  OptionTable table(defaults);
  return table.app().help();
}

std::map<std::string, std::string> option_values(const ServerOptions& options) {
  ServerOptions copy = options;
  return OptionTable(copy).values();
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
  fill_source_defaults(out);
  OptionTable table(out);
  try {
    table.app().parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    std::cout << server_usage();
    return false;
  } catch (const CLI::ExtrasError& e) {
    throw std::invalid_argument(std::string(e.what()) + " (catgs-server --help lists the options)");
  } catch (const CLI::ParseError& e) {
    throw std::invalid_argument(e.what());
  }
  // Encodes are CPU-bound: one worker per core this process may use (its affinity and its
  // cgroup's CPU limit, cpu_quota.h), not per core of the host; x264 adds its own threads.
  EncoderPolicy& policy = out.session.frame.encoder_policy;
  policy.usable_cores = usable_cores();
  if (out.threads == 0) out.threads = std::max(4, policy.usable_cores);
  if (out.render.max_pixels_in_flight == 0)
    out.render.max_pixels_in_flight = 2LL * out.session.max_viewport_width * out.session.max_viewport_height;
  if (out.transport.tls_cert.empty() != out.transport.tls_key.empty())
    throw std::invalid_argument("--tls-cert and --tls-key go together (one is missing)");
  return true;
}

void resolve_access_tokens(ServerOptions& out, const char* env_token, std::ostream& warnings) {
  if (!out.token.empty()) {
    warnings << "catgs-server: warning: --token is visible to every user of this host (/proc/PID/cmdline); "
                "use --token-file FILE or the CATGS_TOKEN environment variable\n";
    out.session.tokens.add(out.token, Role::admin);
  }
  if (!out.token_file.empty()) out.session.tokens.add_file(out.token_file);
  if (env_token && *env_token) out.session.tokens.add(env_token, Role::admin);
}

}  // namespace catgs::server
