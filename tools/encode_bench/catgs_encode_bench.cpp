// catgs-encode-bench: the rate-distortion-latency table behind the encoder policy (issue 35).
//
//   catgs-encode-bench --scene S --trace T.trace|cameras:C.json --width 1920 --height 1080
//       [--renderer auto|cpu|cuda] [--pipeline exact] [--frames 240] [--step 2] [--fps 60]
//       [--settings "crf=23,bitrate=off,threads=2;bitrate=auto,threads=4;..."] [--json OUT]
//       [--dump-dir DIR]   (each row's first stream as files: dump_stream below)
//       [--pictures DIR]   (the middle frame's centre crop: raw.png, and rowN_decoded.png a row)
//
// The trace's poses (every `step`-th: a 120 Hz trace at 60 poses/s) are rendered once, as the
// server would (Camera::from_pose at the given size), keeping each raw 8-bit render and its
// BT.709 I420 planes (the server's conversion). Then, row by row, `sessions` encoders of the
// row's policy (each a session's own stream, on its own thread) encode those frames paced at
// `fps`, as a session's encoder is fed; the first session's access units are decoded by
// libavcodec (h264, or AV1 for `encoder=av1` rows) and compared with the raw renders. Per row:
// encode ms (wall, p50 / p95 / max over every session's frames), process CPU ms a frame, bytes
// (mean, max, first = the IDR), bits a pixel, Mbit/s at fps, PSNR of the decoded frame against
// the raw render (mean, worst 1%, min; 8-bit RGB) and SSIM of its luma (mean, worst 1%). A table on stdout and JSON (with per-frame records). A benchmark: it reports,
// never fails on numbers.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "camera/trace.h"
#include "common/cli_args.h"
#include "common/image_io.h"
#include "encode/frame_encoding.h"
#include "encode/content_rate.h"
#include "encode/encoder_policy.h"
#include "encode/encoder.h"
#include "encode_bench/rd_settings.h"
#include "loadgen/video_decoder.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"

extern "C" {
#include <libavutil/log.h>
}

namespace {

using catgs::encode_bench::RdSetting;
using Clock = std::chrono::steady_clock;

constexpr const char* kDefaultSettings =
    "crf=23,bitrate=off,threads=2;crf=28,bitrate=off,threads=4;crf=23,bitrate=auto,threads=1;"
    "crf=23,bitrate=auto,threads=2;crf=23,bitrate=auto,threads=4;crf=23,bitrate=auto,threads=8;"
    "crf=23,bitrate=auto,threads=4,ir=60";

struct Frame {
  catgs::Image raw;         // the render, rgba8
  catgs::Yuv420Image yuv;   // its I420 planes
  double ceiling_psnr = 0;  // those planes shown with no coding loss, against the render
};

struct Row {
  RdSetting setting;
  catgs::server::EncoderConfig config;    // as the policy made it for `sessions` live sessions
  std::vector<double> encode_ms;          // every session's frames
  std::vector<double> bytes, psnr, ssim;  // the first session's frames
  std::vector<int> key;                   // the first session's IDR flags
  double cpu_ms_per_frame = 0;
  double probe_crf_bpp = 0;  // bpp=auto: the content-rate probe's crf bits a pixel (0: no probe)
};

double process_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) / 1e6;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t i =
      std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size()))) - (p > 0 ? 1 : 0));
  return v[i];
}

double mean(const std::vector<double>& v) {
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

// `--trace`: a trace file, or `cameras:C.json`, a capture's own cameras (INRIA cameras.json)
// interpolated at 120 Hz, half a second a view, as catgs-loadgen's `cameras:` paths.
catgs::Trace bench_trace(const std::string& spec) {
  if (spec.rfind("cameras:", 0) == 0)
    return catgs::interpolate_views(catgs::load_inria_cameras(spec.substr(8)), 120.0, 0.5);
  return catgs::read_trace(spec);
}

std::vector<Frame> render_frames(const catgs::tools::Args& args, int width, int height, int frames, int step) {
  auto model = std::make_shared<const catgs::GaussianModel>(catgs::load_scene(args.require("--scene")));
  const catgs::Trace trace = bench_trace(args.require("--trace"));
  if (trace.empty()) throw std::invalid_argument("--trace holds no pose");
  catgs::RenderOptions options;
  options.pipeline = catgs::parse_pipeline(args.get("--pipeline", "exact"));
  std::string why;
  auto renderer = catgs::make_renderer(args.get("--renderer", "auto"), model, options, &why);
  std::cerr << "renderer: " << renderer->name() << " (" << why << "), " << model->size() << " Gaussians\n";
  std::vector<Frame> out(static_cast<std::size_t>(frames));
  catgs::loadgen::VideoDecoder converter;  // its I420 -> RGB: the 4:2:0 ceiling of a stream's PSNR
  catgs::Image back;
  for (int k = 0; k < frames; ++k) {
    const catgs::Camera& c = trace[static_cast<std::size_t>(k) * step % trace.size()].camera;
    // The server's camera for a pose: position, orientation and vertical fov at the viewport.
    const catgs::Camera cam =
        catgs::Camera::from_pose(c.position(), c.orientation(), c.vertical_fov_deg(), width, height);
    renderer->render(cam, out[k].raw);
    out[k].yuv = catgs::rgba_to_yuv420_bt709(out[k].raw.rgba8.data(), width, height, width * 4);
    const catgs::Yuv420Planes p = out[k].yuv.planes();
    const std::uint8_t* planes[3] = {p.y, p.u, p.v};
    const int strides[3] = {p.y_stride, p.u_stride, p.v_stride};
    converter.to_rgba(planes, strides, width, height, back.rgba8);
    back.width = width;
    back.height = height;
    out[k].ceiling_psnr = std::min(99.0, catgs::psnr_rgba8(back, out[k].raw));
  }
  return out;
}

// The centre crop (a quarter of each side, at least 64 pixels) of an image: what the pictures show.
catgs::Image centre_crop(const catgs::Image& im) {
  const int w = std::min(im.width, std::max(64, im.width / 4)), h = std::min(im.height, std::max(64, im.height / 4));
  const int x0 = (im.width - w) / 2, y0 = (im.height - h) / 2;
  catgs::Image out;
  out.width = w;
  out.height = h;
  out.rgba8.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 4);
  for (int y = 0; y < h; ++y)
    std::copy_n(&im.rgba8[(static_cast<std::size_t>(y0 + y) * static_cast<std::size_t>(im.width) + x0) * 4],
                static_cast<std::size_t>(w) * 4,
                &out.rgba8[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) * 4]);
  return out;
}

// One session's stream: frame k starts at start + k / fps, or as soon as frame k - 1 is done.
void encode_session(const std::string& kind, const catgs::server::EncoderConfig& config,
                    const std::vector<Frame>& frames, int fps, Clock::time_point start, std::vector<double>& encode_ms,
                    std::vector<std::vector<std::uint8_t>>* units) {
  const std::unique_ptr<catgs::server::Encoder> made = catgs::server::make_encoder(kind, config);
  catgs::server::Encoder& encoder = *made;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    std::this_thread::sleep_until(start +
                                  std::chrono::microseconds(static_cast<long>(static_cast<double>(k) * 1e6 / fps)));
    const catgs::server::EncodedFrame e = encoder.encode_yuv420(frames[k].yuv.planes(), false);
    encode_ms.push_back(e.encode_ms);
    if (units) units->push_back(e.data);
  }
}

// `pictures`: where the middle frame's decoded centre crop goes (DIR/rowN_decoded.png; "" none).
Row run_row(const RdSetting& s, const std::vector<Frame>& frames, int width, int height, int fps,
            std::vector<std::vector<std::uint8_t>>& units, const std::string& pictures) {
  Row row;
  row.setting = s;
  // The row's settings as a server session's frame gets them (encode/frame_encoding.h, the one
  // call the server makes): the row's policy, `sessions` live, no client or link cap; at the
  // server's kStreamFps (--fps paces the frames only).
  catgs::server::FrameEncodeInputs in;
  in.width = width;
  in.height = height;
  in.live_sessions = s.sessions;
  const catgs::server::FrameEncoding first = catgs::server::frame_encoding(s.policy, in);
  if (s.policy.content_rate && s.policy.bitrate_kbps < 0) {
    // As a server session: the first kProbeFrames moving frames (after the probe's IDR) measured,
    // with the stream's preset and threads (FramePipeline::probe_content_rate).
    catgs::server::ContentRateProbe probe(s.policy, width, height, std::max(1, first.threads), first.preset);
    for (std::size_t k = 0; k < frames.size() && !probe.done(); ++k) probe.add(frames[k].yuv.planes());
    row.probe_crf_bpp = probe.crf_bits_per_pixel();
    in.probed_bits_per_pixel = catgs::server::content_bits_per_pixel(row.probe_crf_bpp);
  }
  row.config = catgs::server::frame_encoding(s.policy, in).config;
  std::vector<std::vector<double>> times(static_cast<std::size_t>(s.sessions));
  units.clear();
  const double cpu0 = process_cpu_ms();
  const auto start = Clock::now() + std::chrono::milliseconds(20);
  std::vector<std::thread> threads;
  for (int i = 0; i < s.sessions; ++i)
    threads.emplace_back(encode_session, std::cref(s.encoder), std::cref(row.config), std::cref(frames), fps, start,
                         std::ref(times[i]), i == 0 ? &units : nullptr);
  for (auto& t : threads) t.join();
  row.cpu_ms_per_frame = (process_cpu_ms() - cpu0) / static_cast<double>(frames.size() * s.sessions);
  for (const auto& t : times) row.encode_ms.insert(row.encode_ms.end(), t.begin(), t.end());
  catgs::loadgen::VideoDecoder decoder(s.encoder == "av1" ? "av1" : "h264");
  catgs::Image decoded;
  for (std::size_t k = 0; k < units.size(); ++k) {
    const std::string au(units[k].begin(), units[k].end());
    row.bytes.push_back(static_cast<double>(au.size()));
    row.key.push_back(k == 0 ? 1 : 0);
    if (!decoder.decode(au, decoded.rgba8, decoded.width, decoded.height))
      throw std::runtime_error("setting '" + s.label + "': frame " + std::to_string(k) + " did not decode");
    row.psnr.push_back(std::min(99.0, catgs::psnr_rgba8(decoded, frames[k].raw)));
    row.ssim.push_back(catgs::ssim_luma_rgba8(decoded, frames[k].raw));
    if (!pictures.empty() && k == units.size() / 2) catgs::write_png(centre_crop(decoded), pictures + "_decoded.png");
  }
  return row;
}

// The first session's stream of row `index` as files another tool can read: DIR/rowN.h264 (Annex
// B: ffmpeg -f h264) or DIR/rowN.obu (AV1 low-overhead OBUs, one temporal unit after another:
// ffmpeg -f obu), and DIR/rowN.json (its codec, size and each access unit's bytes, in order:
// tests/e2e/decode_bench.mjs feeds them to WebCodecs).
void dump_stream(const std::string& dir, std::size_t index, const Row& row,
                 const std::vector<std::vector<std::uint8_t>>& units, int width, int height, int fps) {
  const bool av1 = row.setting.encoder == "av1";
  const std::string base = dir + "/row" + std::to_string(index);
  std::ofstream bits(base + (av1 ? ".obu" : ".h264"), std::ios::binary);
  std::vector<std::size_t> sizes;
  for (const auto& u : units) {
    bits.write(reinterpret_cast<const char*>(u.data()), static_cast<std::streamsize>(u.size()));
    sizes.push_back(u.size());
  }
  if (!bits) throw std::runtime_error("cannot write " + base + (av1 ? ".obu" : ".h264"));
  std::ofstream(base + ".json") << nlohmann::json{{"label", row.setting.label},
                                                  {"codec", av1 ? "av1" : "h264"},
                                                  {"width", width},
                                                  {"height", height},
                                                  {"fps", fps},
                                                  {"sizes", sizes}}
                                       .dump()
                                << "\n";
}

nlohmann::json row_json(const Row& r, int width, int height, int fps) {
  const double bpp = mean(r.bytes) * 8 / (static_cast<double>(width) * height);
  return {
      {"label", r.setting.label},
      {"sessions", r.setting.sessions},
      {"threads", r.config.threads},
      {"encoder", r.setting.encoder},
      {"preset", r.setting.encoder == "av1" ? "speed " + std::to_string(r.config.av1_speed) : r.config.x264_preset},
      {"crf", r.config.crf},
      {"bitrate_kbps", r.config.bitrate_kbps},
      {"vbv_ms", r.config.vbv_buffer_ms},
      {"intra_refresh_frames", r.config.intra_refresh_frames},
      {"encode_ms",
       {{"p50", percentile(r.encode_ms, 0.5)},
        {"p95", percentile(r.encode_ms, 0.95)},
        {"max", percentile(r.encode_ms, 1.0)},
        {"mean", mean(r.encode_ms)}}},
      {"cpu_ms_per_frame", r.cpu_ms_per_frame},
      {"bytes", {{"mean", mean(r.bytes)}, {"max", percentile(r.bytes, 1.0)}, {"first", r.bytes.front()}}},
      {"bits_per_pixel", bpp},
      {"cap_bits_per_pixel",
       static_cast<double>(r.config.bitrate_kbps) * 1000.0 / (static_cast<double>(width) * height * fps)},
      {"probe_crf_bits_per_pixel", r.probe_crf_bpp},
      {"mbit_s", mean(r.bytes) * 8 * fps / 1e6},
      {"psnr_db", {{"mean", mean(r.psnr)}, {"worst_1pct", percentile(r.psnr, 0.01)}, {"min", percentile(r.psnr, 0.0)}}},
      {"ssim", {{"mean", mean(r.ssim)}, {"worst_1pct", percentile(r.ssim, 0.01)}}},
      {"frames", {{"encode_ms", r.encode_ms}, {"bytes", r.bytes}, {"psnr_db", r.psnr}, {"ssim", r.ssim}}}};
}

void print_table(const nlohmann::json& rows) {
  std::cout << "| setting | sessions | preset | threads | kbit/s cap | encode ms p50 / p95 / max | CPU ms a frame | "
               "KiB mean / max / IDR | bits a pixel | Mbit/s | PSNR dB mean / worst 1% / min | SSIM mean / worst 1% |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|\n"
            << std::fixed;
  for (const auto& r : rows) {
    std::cout << std::setprecision(2) << "| " << r["label"].get<std::string>() << " | " << r["sessions"] << " | "
              << r["preset"].get<std::string>() << " | " << r["threads"] << " | " << r["bitrate_kbps"] << " | "
              << r["encode_ms"]["p50"].get<double>() << " / " << r["encode_ms"]["p95"].get<double>() << " / "
              << r["encode_ms"]["max"].get<double>() << " | " << r["cpu_ms_per_frame"].get<double>() << " | "
              << std::setprecision(1) << r["bytes"]["mean"].get<double>() / 1024 << " / "
              << r["bytes"]["max"].get<double>() / 1024 << " / " << r["bytes"]["first"].get<double>() / 1024 << " | "
              << std::setprecision(4) << r["bits_per_pixel"].get<double>() << " | " << std::setprecision(2)
              << r["mbit_s"].get<double>() << " | " << r["psnr_db"]["mean"].get<double>() << " / "
              << r["psnr_db"]["worst_1pct"].get<double>() << " / " << r["psnr_db"]["min"].get<double>() << " | "
              << std::setprecision(4) << r["ssim"]["mean"].get<double>() << " / "
              << r["ssim"]["worst_1pct"].get<double>() << " |\n";
  }
}

int usable_cores() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

}  // namespace

constexpr const char* kUsage =
    "usage: catgs-encode-bench --scene S --trace T.trace|cameras:C.json --width 1920 --height 1080\n"
    "    [--renderer auto|cpu|cuda] [--pipeline exact] [--frames 240] [--step 2] [--fps 60] [--cores N]\n"
    "    [--settings \"crf=23,bitrate=off,threads=2;bitrate=auto,threads=4;...\"] [--json OUT]\n"
    "    [--dump-dir DIR] (each row's first stream as files) [--pictures DIR] (the middle frame's centre crop)\n"
    "Renders the trace once, encodes it with each row's settings paced at --fps, decodes and compares with\n"
    "the raw render (PSNR, SSIM): a table on stdout, JSON with --json. tools/README.md says more.\n";

int main(int argc, char** argv) {
  av_log_set_level(AV_LOG_ERROR);  // x264's banner and statistics per encoder
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::cout << kUsage;
      return 0;
    }
  try {
    const catgs::tools::Args args(argc, argv,
                                  {"--scene", "--trace", "--renderer", "--pipeline", "--width", "--height", "--frames",
                                   "--step", "--fps", "--settings", "--json", "--cores", "--dump-dir", "--pictures"});
    const int width = args.get_int("--width", 1920), height = args.get_int("--height", 1080);
    const int frames = args.get_int("--frames", 240), step = args.get_int("--step", 2), fps = args.get_int("--fps", 60);
    if (frames < 1 || step < 1 || fps < 1) throw std::invalid_argument("--frames, --step and --fps must be >= 1");
    const int cores = args.get_int("--cores", usable_cores());
    const auto settings = catgs::encode_bench::parse_rd_settings(args.get("--settings", kDefaultSettings), cores);
    const std::vector<Frame> rendered = render_frames(args, width, height, frames, step);
    std::vector<double> ceiling;
    for (const Frame& f : rendered) ceiling.push_back(f.ceiling_psnr);
    nlohmann::json rows = nlohmann::json::array();
    if (args.has("--dump-dir")) std::filesystem::create_directories(args.get("--dump-dir"));
    const std::string pictures = args.get("--pictures", "");
    if (!pictures.empty()) {
      std::filesystem::create_directories(pictures);
      catgs::write_png(centre_crop(rendered[rendered.size() / 2].raw), pictures + "/raw.png");
    }
    for (const RdSetting& s : settings) {
      std::vector<std::vector<std::uint8_t>> units;
      const Row row = run_row(s, rendered, width, height, fps, units,
                              pictures.empty() ? "" : pictures + "/row" + std::to_string(rows.size()));
      if (args.has("--dump-dir")) dump_stream(args.get("--dump-dir"), rows.size(), row, units, width, height, fps);
      rows.push_back(row_json(row, width, height, fps));
      std::cerr << "done: " << s.label << "\n";
    }
    std::cout << "catgs-encode-bench " << width << "x" << height << " at " << fps << " frames/s, " << frames
              << " frames, " << cores << " cores; the I420 planes shown with no coding loss: PSNR " << mean(ceiling)
              << " dB mean, " << percentile(ceiling, 0.0) << " min (the 4:2:0 ceiling)\n";
    print_table(rows);
    if (args.has("--json")) {
      nlohmann::json j{{"scene", args.get("--scene")},
                       {"trace", args.get("--trace")},
                       {"width", width},
                       {"height", height},
                       {"fps", fps},
                       {"frames", frames},
                       {"step", step},
                       {"cores", cores},
                       {"ceiling_psnr_db", {{"mean", mean(ceiling)}, {"min", percentile(ceiling, 0.0)}}},
                       {"rows", rows}};
      std::ofstream(args.get("--json")) << j.dump(1) << "\n";
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "catgs-encode-bench: " << e.what() << "\n";
    return 1;
  }
}
