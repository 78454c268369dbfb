// catgs-loadgen: N concurrent sessions (one thread each) replay camera traces against a running
// catgs-server and report frames, FPS, pose-to-frame latency, bytes/s, dropped and stale frames,
// errors and the server's stage times, as a table and optionally JSON, with a progress line on
// stderr while it runs. It does not pass or fail on time, except in ramp mode, where it searches
// for the largest session count that holds the given bounds; it fails (exit 1) when a session
// failed or a reference check did, and says so with exit 3 when the server refused sessions.
// Each trace is made once a run and shared by its sessions (loadgen/trace_cache.h), and each run
// or ramp step prints the client's own CPU time, warning when it passed a tenth of the host's
// cores: then the client may have bound the run, not the server (issue 92).
//
//   catgs-loadgen --port 8080 --sessions 4 --size 1280x720 --trace orbit --seconds 10
//   catgs-loadgen --sessions 4 --trace orbit,real:C.json --scene S.ply --size 1280x720,640x480
//   catgs-loadgen --ramp --sessions 32 --max-p95-ms 25 --min-fps 60 --json ramp.json
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <sched.h>
#include <sys/resource.h>

#include <nlohmann/json.hpp>

#include "lod/lod_build.h"
#include "scene/ply_io.h"
#include "scene/scene_peek.h"
#include "common/cli_args.h"
#include "loadgen/load_report.h"
#include "loadgen/load_session.h"

using namespace catgs;
using namespace catgs::loadgen;

namespace {

const char* kUsage =
    "usage: catgs-loadgen [options]\n"
    "  --host H --port N        server (default 127.0.0.1:8080)\n"
    "  --tls                    wss:// (a server with --tls-cert); its certificate is not checked\n"
    "  --sessions N             concurrent sessions (default 1; the ramp's upper limit)\n"
    "  --size WxH[,WxH...]      frame sizes, assigned to sessions in turn (default 1280x720)\n"
    "  --width W --height H     same as --size WxH\n"
    "  --trace T[,T...]         orbit | real:C.json | cameras:C.json | FILE.trace, in turn\n"
    "                           (default orbit)\n"
    "  --scene FILE             the server's scene, for real: traces (and a better orbit)\n"
    "  --scene-name NAME        ask the server for this scene (a name from its GET /scenes;\n"
    "                           default: its first)\n"
    "  --offset-s S             session i starts i*S seconds into its trace (default 0.37)\n"
    "  --arrive-every-ms MS     session i connects i*MS ms after the run starts (visitors\n"
    "                           arriving one by one; default 0: all at once)\n"
    "  --rate HZ                poses per second per session (default 60; 0 = closed loop)\n"
    "  --depth D                closed loop: poses outstanding (default 1)\n"
    "  --seconds S              how long each run sends poses (default 10)\n"
    "  --decode 0|1             decode every frame with libavcodec (default 0)\n"
    "  --av1                    offer AV1 in Hello (before H.264): the server streams it where\n"
    "                           its policy affords it; frames of either codec are decoded\n"
    "  --check-every N          decode, and compare every Nth frame with the CPU reference\n"
    "                           render of its pose at the LOD bound it was drawn at (needs\n"
    "                           --scene; slows the client down)\n"
    "  --check-min-psnr DB      a checked frame below this fails the run (default 30)\n"
    "  --warmup N               first N frames of a session left out of the statistics (5)\n"
    "  --timeline               every frame's arrival time, latency, size, bytes and time in\n"
    "                           the server in the JSON\n"
    "  --receipts 0|1|2         each pose carries the newest frame's arrival time, as the page's\n"
    "                           do (the server's rate controller reads the queue from them; 1,\n"
    "                           0 with --check-every: its renders between reads stamp them late);\n"
    "                           none for a frame read after 50 ms away from the socket, except\n"
    "                           with 2 (as clients before issue 64: late reads look like a queue)\n"
    "  --warmup-s S             frames of the poses sent in a session's first S seconds left\n"
    "                           out too (0; the settling time a slow link's controller gets)\n"
    "  --stale-ms MS            frames later than this count as stale (default 100)\n"
    "  --read-stall-ms A-B      a busy client: after each read, stall a random A..B ms before\n"
    "                           reading and sending again (as a page whose thread is busy)\n"
    "  --still-s S              after --seconds the camera stops: no more poses, read on for S s,\n"
    "                           and compare the picture shown 1 s, 3 s after and at the end with\n"
    "                           the CPU reference render of its pose (needs --scene; decodes)\n"
    "  --record DIR             record each session into DIR/session_I for the shown-picture\n"
    "                           measure (catgs-shown): the stream, each frame's arrival and pose,\n"
    "                           the poses, the trace (not with --ramp or --av1)\n"
    "  --link-rtt-ms MS         emulate a link's round trip: each pose sent is the trace's pose\n"
    "                           MS/2 ago; the recording adds the frames' MS/2 (default 0)\n"
    "  --link-mbit R            the emulated link's rate: the stream is capped at 80% of it\n"
    "                           (Quality) and the recording queues frames at R (default 0: none)\n"
    "  --stereo WxH@HZ          headsets (issue 94): each session streams both eyes of W x H\n"
    "                           side by side (the stream 2W x H) and sends HZ stereo poses a\n"
    "                           second (replacing --size and --rate): the trace's camera as the\n"
    "                           head, turning +-25 degrees every 0.8 s (196 degrees/s at most),\n"
    "                           eyes 63 mm apart; latency and FPS are each eye's (one frame\n"
    "                           holds both)\n"
    "  --mono-eye               with --stereo: stream one eye's view alone (W x H, a mono pose of\n"
    "                           the left eye, the eye's vertical field of view): its cost, against\n"
    "                           which a stereo frame's is measured\n"
    "  --token T                Hello token\n"
    "  --json FILE              write the report (every ramp step) as JSON\n"
    "  --ramp                   run 1, 2, 4, ... sessions until a bound breaks\n"
    "  --ramp-step x2|+K        session counts double (default) or grow by K\n"
    "  --ramp-start N           the ramp's first session count (default 1)\n"
    "  --max-p95-ms MS          ramp bound: pooled p95 pose-to-frame latency\n"
    "  --min-fps F              ramp bound: the slowest session's FPS\n"
    "  --progress S             a progress line on stderr every S seconds (default 1; 0: none)\n"
    "after each run or ramp step: the client's own CPU time (JSON client_cpu), with a warning when\n"
    "it passed 10% of the usable cores (then the client may have bound the run)\n"
    "exit status: 0 every session streamed; 1 a session failed (no connection, lost connection,\n"
    "server Error, no frame, bad reference check); 3 the server refused sessions (none failed);\n"
    "2 bad arguments. A ramp exits 0 when it ran (its bound breaking is its answer).\n";

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

std::pair<int, int> parse_size(const std::string& s) {
  const auto x = s.find('x');
  if (x == std::string::npos) throw std::invalid_argument("size '" + s + "' is not WxH");
  return {std::stoi(s.substr(0, x)), std::stoi(s.substr(x + 1))};
}

// --stereo WxH@HZ: an eye's size and the display's rate.
struct StereoSpec {
  int eye_width = 0, eye_height = 0;
  double display_hz = 0;
};
StereoSpec parse_stereo(const std::string& s) {
  const auto at = s.find('@');
  StereoSpec spec;
  try {
    if (at == std::string::npos) throw std::invalid_argument("no @");
    std::tie(spec.eye_width, spec.eye_height) = parse_size(s.substr(0, at));
    spec.display_hz = std::stod(s.substr(at + 1));
  } catch (const std::exception&) {
    spec.eye_width = 0;
  }
  if (spec.eye_width < 8 || spec.eye_height < 16 || spec.eye_width % 2 != 0 || !(spec.display_hz > 0))
    throw std::invalid_argument("--stereo wants WxH@HZ, an eye's even width, its height and the display's rate (got '" +
                                s + "')");
  return spec;
}

// "[3.0 s] sessions 4 open, 1 refused, 0 failed; frames 180 (59.8/s), poses 360"
std::string progress_line(const Progress& p, int sessions, double elapsed_s, double seconds,
                          std::uint64_t frames_before, double interval_s) {
  char line[256];
  const std::uint64_t frames = p.frames.load();
  std::snprintf(line, sizeof(line),
                "[%.1f/%.1f s] sessions: %d open, %d refused, %d failed, %d of %d done; frames %llu (%.1f/s), "
                "poses %llu\n",
                elapsed_s, seconds, p.open.load(), p.refused.load(), p.failed.load(), p.finished.load(), sessions,
                static_cast<unsigned long long>(frames),
                interval_s > 0 ? static_cast<double>(frames - frames_before) / interval_s : 0.0,
                static_cast<unsigned long long>(p.poses.load()));
  return line;
}

// This process's CPU time so far, user + system seconds (getrusage).
double process_cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  const auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return seconds(u.ru_utime) + seconds(u.ru_stime);
}

// The cores this process may run on (its affinity mask; the host's when unrestricted).
int usable_cores() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
  return std::max(1u, std::thread::hardware_concurrency());
}

// A client busier than this share of the host's cores may have bound the run, not the server
// (issue 92: on the big cities the fits per session took more cores than the server).
constexpr double kClientBusyShare = 0.1;

// What the client itself cost over a run (or a ramp step) of `sessions` sessions: its CPU seconds
// from `cpu_before`, over the wall seconds from `start`. Printed, with a warning when it passed
// kClientBusyShare of the cores, and returned for the JSON.
nlohmann::json client_cost(double cpu_before, std::chrono::steady_clock::time_point start, int sessions) {
  const double cpu_s = process_cpu_s() - cpu_before;
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double cores = wall_s > 0 ? cpu_s / wall_s : 0.0;
  const int host = usable_cores();
  const bool busy = cores > kClientBusyShare * host;
  std::printf("client CPU: %.2f s (user + sys) over %.1f s: %.3f cores, %.4f a session (%d usable cores)\n", cpu_s,
              wall_s, cores, cores / std::max(1, sessions), host);
  if (busy)
    std::printf(
        "catgs-loadgen: the client used %.0f%% of the %d cores, over the %.0f%% it should: it may have "
        "bound this run, not the server\n",
        100.0 * cores / host, host, 100.0 * kClientBusyShare);
  return {{"cpu_s", cpu_s},       {"wall_s", wall_s},
          {"cores", cores},       {"cores_per_session", cores / std::max(1, sessions)},
          {"usable_cores", host}, {"busy", busy}};
}

// Runs `n` sessions at once, one thread each; prints a progress line every `progress_s` seconds
// (0: none) while they run.
std::vector<SessionResult> run_sessions(int n, const std::vector<LoadSessionConfig>& templates, double progress_s = 0) {
  std::vector<SessionResult> results(static_cast<std::size_t>(n));
  std::vector<std::thread> threads;
  Progress progress;
  for (int i = 0; i < n; ++i) {
    LoadSessionConfig c = templates[static_cast<std::size_t>(i) % templates.size()];
    c.index = i;
    c.offset_s *= i;
    c.arrive_after_s *= i;
    c.progress = &progress;
    if (!c.record_dir.empty()) c.record_dir += "/session_" + std::to_string(i);
    threads.emplace_back([c, &results, i] { results[static_cast<std::size_t>(i)] = run_load_session(c); });
  }
  if (progress_s > 0) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    auto last = start;
    std::uint64_t frames_before = 0;
    while (progress.finished.load() < n) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      const auto now = Clock::now();
      const double since = std::chrono::duration<double>(now - last).count();
      if (since < progress_s) continue;
      std::cerr << progress_line(progress, n, std::chrono::duration<double>(now - start).count(),
                                 templates.front().seconds, frames_before, since);
      frames_before = progress.frames.load();
      last = now;
    }
  }
  for (auto& t : threads) t.join();
  return results;
}

// The reference checks' scene: `scene` (read from `path`) with its level of detail: its own where
// it brings one (a compact scene), else built as the server builds it
// (server/process/scene_with_lod.cpp: default options, a compressed PLY's chunks kept as the
// leaves), so each checked frame is compared with the reference at the bound the server drew it
// at, not with full detail, which a coarse cut differs from by design (RESULTS.md, "Level of
// detail"). A scene the server serves without its level of detail reports bound 0, whose
// reference is the leaves: the scene bit for bit.
std::shared_ptr<const GaussianModel> reference_scene(const std::string& path,
                                                     const std::shared_ptr<const GaussianModel>& scene) {
  if (!scene->lod.empty()) return scene;
  LodBuildOptions o;
  try {
    o.keep_order = peek_scene(path).format == "compressed_ply";
  } catch (const std::exception&) {
    o.keep_order = false;  // read already: a file that will not peek is not a compressed PLY
  }
  LodBuildReport report;
  auto lod = std::make_shared<const GaussianModel>(build_lod(*scene, o, &report));
  std::cout << "reference: level of detail built in " << static_cast<long>(report.seconds * 1000) << " ms ("
            << lod->size() - lod_leaf_gaussians(*lod) << " merged Gaussians)\n";
  return lod;
}

// The settings every session shares, from the command line.
LoadSessionConfig base_config(const tools::Args& args) {
  LoadSessionConfig base;
  base.host = args.get("--host", base.host);
  base.port = args.get_int("--port", base.port);
  base.tls = args.has("--tls");
  base.token = args.get("--token");
  base.scene_name = args.get("--scene-name");
  base.offset_s = args.get_double("--offset-s", 0.37);
  base.arrive_after_s = args.get_double("--arrive-every-ms", 0) / 1000.0;
  base.rate_hz = args.get_double("--rate", 60);
  base.depth = std::max(1, args.get_int("--depth", 1));
  base.seconds = args.get_double("--seconds", 10);
  base.decode = args.get("--decode", "0") == "1";
  base.offer_av1 = args.has("--av1");
  base.check_every = std::max(0, args.get_int("--check-every", 0));
  base.check_min_psnr = args.get_double("--check-min-psnr", 30);
  if (base.check_every > 0 && !args.has("--scene"))
    throw std::invalid_argument("--check-every needs --scene (the reference renders it)");
  base.warmup_frames = args.get_int("--warmup", 5);
  base.warmup_s = args.get_double("--warmup-s", 0.0);
  base.timeline = args.has("--timeline");
  // A reference check renders on the CPU between reads, so the frames that arrive meanwhile are
  // stamped when it ends, as if they had queued on the link: no receipts unless asked for.
  const int receipts = args.get_int("--receipts", base.check_every > 0 ? 0 : 1);
  base.receipts = receipts != 0;
  base.late_receipts = receipts == 2;
  base.stale_ms = args.get_double("--stale-ms", 100);
  if (args.has("--read-stall-ms")) {
    const std::string range = args.get("--read-stall-ms");
    const auto dash = range.find('-');
    try {
      base.read_stall_min_ms = std::stoi(range.substr(0, dash));
      base.read_stall_max_ms = dash == std::string::npos ? base.read_stall_min_ms : std::stoi(range.substr(dash + 1));
    } catch (const std::exception&) {
      base.read_stall_min_ms = -1;
    }
    if (base.read_stall_min_ms < 0 || base.read_stall_max_ms < base.read_stall_min_ms)
      throw std::invalid_argument("--read-stall-ms wants A-B milliseconds, 0 <= A <= B (got '" + range + "')");
  }
  base.still_s = args.get_double("--still-s", 0);
  if (base.still_s < 0) throw std::invalid_argument("--still-s must be >= 0 seconds");
  if (base.still_s > 0 && !args.has("--scene"))
    throw std::invalid_argument("--still-s needs --scene (the reference renders the still pose)");
  if (args.get_double("--progress", 1) < 0) throw std::invalid_argument("--progress must be >= 0 seconds");
  base.record_dir = args.get("--record");
  if (!base.record_dir.empty() && args.has("--ramp"))
    throw std::invalid_argument("--record records one run, not a ramp (each step would replace the last)");
  if (!base.record_dir.empty() && base.offer_av1)
    throw std::invalid_argument("--record holds H.264 only: leave out --av1");
  base.link.rtt_ms = args.get_double("--link-rtt-ms", 0);
  base.link.rate_mbit = args.get_double("--link-mbit", 0);
  if (base.link.rtt_ms < 0 || base.link.rate_mbit < 0)
    throw std::invalid_argument("--link-rtt-ms and --link-mbit must be >= 0");
  if (args.has("--stereo")) {
    base.stereo = true;
    base.rate_hz = parse_stereo(args.get("--stereo")).display_hz;
    base.mono_eye = args.has("--mono-eye");
    if (base.check_every > 0 || base.still_s > 0 || !base.record_dir.empty())
      throw std::invalid_argument("--stereo has no reference check, still check or recording (they compare one view)");
  }
  base.traces = std::make_shared<TraceCache>();  // each trace made once a run (issue 92)
  if (args.has("--scene")) {
    base.scene = std::make_shared<const GaussianModel>(load_scene(args.get("--scene")));
    std::cout << "scene " << args.get("--scene") << ": " << base.scene->size() << " Gaussians\n";
    if (base.check_every > 0 || base.still_s > 0)
      base.reference_scene = reference_scene(args.get("--scene"), base.scene);
  }
  return base;
}

// A reference check (--check-every) that found a bad frame, or checked none, fails the session.
bool check_failed(const SessionResult& r, const LoadSessionConfig& base) {
  return !r.refused && base.check_every > 0 && (r.check_failures > 0 || r.checked == 0);
}

// The exit status of a run (see kUsage): 1 when a session failed or a reference check did, else
// 3 when the server refused sessions, else 0.
int run_exit_code(const std::vector<SessionResult>& results, const LoadSessionConfig& base) {
  bool failed = false, refused = false;
  for (const auto& r : results) {
    refused = refused || r.refused;
    if (r.refused) continue;
    failed = failed || session_status(r) == "failed" || check_failed(r, base);
  }
  return failed ? 1 : refused ? 3 : 0;
}

// One run of `sessions` sessions; returns its exit status.
int run_once(int max_sessions, const std::vector<LoadSessionConfig>& templates, const LoadSessionConfig& base,
             double progress_s, nlohmann::json& report) {
  const double cpu_before = process_cpu_s();
  const auto start = std::chrono::steady_clock::now();
  const auto results = run_sessions(max_sessions, templates, progress_s);
  std::cout << format_table(results);
  report["run"] = run_json(results);
  report["run"]["client_cpu"] = client_cost(cpu_before, start, max_sessions);
  const int code = run_exit_code(results, base);
  if (code != 0) {
    const RunSummary t = summarize_run(results);
    std::cerr << "catgs-loadgen: " << t.failed << " of " << t.sessions << " sessions failed, " << t.refused
              << " refused by the server";
    // Which of the check's two failures, so a failed run says whether the picture or the count was short.
    int low = 0, unchecked = 0;
    double worst = 0;
    for (const auto& r : results) {
      if (!check_failed(r, base)) continue;
      if (r.checked == 0) {
        ++unchecked;
      } else {
        worst = low++ == 0 ? r.psnr_min : std::min(worst, r.psnr_min);
      }
    }
    if (low > 0) {
      char lowest[32];
      std::snprintf(lowest, sizeof lowest, "%.2f", worst);
      std::cerr << ", " << low << " failed the reference check (a frame below " << base.check_min_psnr
                << " dB; the lowest " << lowest << " dB)";
    }
    if (unchecked > 0) std::cerr << ", " << unchecked << " checked no frame (--check-every " << base.check_every << ")";
    std::cerr << " (exit " << code << ")\n";
  }
  return code;
}

// --ramp: 1, 2, 4, ... (or +K) sessions until one step breaks the bounds.
void run_ramp(const tools::Args& args, int max_sessions, const std::vector<LoadSessionConfig>& templates,
              double progress_s, nlohmann::json& report) {
  const std::string step = args.get("--ramp-step", "x2");
  const int add = step.rfind('+', 0) == 0 ? std::stoi(step.substr(1)) : 0;
  if (step != "x2" && add <= 0) throw std::invalid_argument("--ramp-step must be x2 or +K");
  const double max_p95 = args.get_double("--max-p95-ms", 0), min_fps = args.get_double("--min-fps", 0);
  int held = 0;
  report["ramp"] = nlohmann::json::array();
  const int start = args.get_int("--ramp-start", 1);
  if (start < 1) throw std::invalid_argument("--ramp-start must be >= 1");
  for (int n = start; n <= max_sessions; n = add ? n + add : 2 * n) {
    const double cpu_before = process_cpu_s();
    const auto started = std::chrono::steady_clock::now();
    const auto results = run_sessions(n, templates, progress_s);
    const RunSummary t = summarize_run(results);
    char broken[96] = "";
    if (t.refused)
      std::snprintf(broken, sizeof(broken), "%d sessions refused", t.refused);
    else if (t.errors)
      std::snprintf(broken, sizeof(broken), "%llu errors", static_cast<unsigned long long>(t.errors));
    else if (max_p95 > 0 && t.latency.p95 > max_p95)
      std::snprintf(broken, sizeof(broken), "p95 %.1f ms", t.latency.p95);
    else if (min_fps > 0 && t.fps_min < min_fps)
      std::snprintf(broken, sizeof(broken), "slowest session %.1f FPS", t.fps_min);
    std::printf("--- %d session(s): %s%s\n", n, broken[0] ? "broke: " : "held", broken);
    std::cout << format_table(results);
    nlohmann::json step_json = run_json(results);
    step_json["client_cpu"] = client_cost(cpu_before, started, n);
    step_json["held"] = broken[0] == 0;
    step_json["broken_by"] = broken;
    report["ramp"].push_back(step_json);
    if (broken[0]) break;
    held = n;
  }
  std::printf("ramp: largest session count that held: %d (bounds: p95 <= %g ms, min FPS >= %g; 0 = none)\n", held,
              max_p95, min_fps);
  report["largest_sessions_held"] = held;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const tools::Args args(argc, argv, {"--host",           "--port",          "--sessions",        "--size",
                                        "--width",          "--height",        "--arrive-every-ms", "--trace",
                                        "--scene",          "--scene-name",    "--offset-s",        "--rate",
                                        "--depth",          "--seconds",       "--decode",          "--check-every",
                                        "--check-min-psnr", "--warmup",        "--warmup-s",        "--stale-ms",
                                        "--token",          "--json",          "--ramp!",           "--ramp-step",
                                        "--ramp-start",     "--max-p95-ms",    "--min-fps",         "--progress",
                                        "--tls!",           "--help!",         "--timeline!",       "--av1!",
                                        "--receipts",       "--read-stall-ms", "--still-s",         "--record",
                                        "--link-rtt-ms",    "--link-mbit",     "--stereo",          "--mono-eye!"});
    if (args.has("--help")) {
      std::cout << kUsage;
      return 0;
    }
    const LoadSessionConfig base = base_config(args);
    std::vector<std::string> sizes = split(args.get("--size", "1280x720"));
    if (args.has("--width") || args.has("--height"))
      sizes = {std::to_string(args.get_int("--width", 1280)) + "x" + std::to_string(args.get_int("--height", 720))};
    if (base.stereo) {  // the stream holds both eyes
      const StereoSpec s = parse_stereo(args.get("--stereo"));
      sizes = {std::to_string((base.mono_eye ? 1 : 2) * s.eye_width) + "x" + std::to_string(s.eye_height)};
      std::printf("headsets: %s of %dx%d (%s), %g poses a second\n",
                  base.mono_eye ? "the left eye alone" : "two eyes side by side", s.eye_width, s.eye_height,
                  sizes[0].c_str(), s.display_hz);
    }
    const std::vector<std::string> traces = split(args.get("--trace", "orbit"));
    if (sizes.empty() || traces.empty()) throw std::invalid_argument("--size and --trace need values");
    // One template per (size, trace) turn; session i takes template i mod count.
    std::vector<LoadSessionConfig> templates;
    for (std::size_t i = 0; i < std::max(sizes.size(), traces.size()); ++i) {
      LoadSessionConfig c = base;
      std::tie(c.width, c.height) = parse_size(sizes[i % sizes.size()]);
      c.trace = traces[i % traces.size()];
      templates.push_back(c);
    }
    const int max_sessions = std::max(1, args.get_int("--sessions", 1));

    nlohmann::json report;
    report["config"] = {{"rate_hz", base.rate_hz},
                        {"seconds", base.seconds},
                        {"decode", base.decode},
                        {"check_every", base.check_every},
                        {"check_min_psnr", base.check_min_psnr},
                        {"sizes", sizes},
                        {"traces", traces},
                        {"stale_ms", base.stale_ms},
                        {"stereo", base.stereo}};
    int exit_code = 0;
    const double progress_s = args.get_double("--progress", 1);
    if (!args.has("--ramp")) {
      exit_code = run_once(max_sessions, templates, base, progress_s, report);
    } else {
      run_ramp(args, max_sessions, templates, progress_s, report);
    }
    report["traces_made"] = base.traces->made();
    if (args.has("--json")) {
      std::ofstream(args.get("--json")) << report.dump(1) << "\n";
      std::cout << "JSON: " << args.get("--json") << "\n";
    }
    return exit_code;
  } catch (const std::exception& e) {
    std::cerr << "catgs-loadgen: " << e.what() << "\n" << kUsage;
    return 2;
  }
}
