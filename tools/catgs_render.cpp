// catgs-render: renders views of a scene to PNG with any renderer and pipeline.
//
//   catgs-render --scene S.ply --cameras C.json --view K --width W --height H
//                --pipeline vanilla|exact --renderer cpu|cuda|auto --out F.png
//   catgs-render --scene S.ply --cameras C.json --all --fps 30 --out-dir DIR    (interpolated path)
//   catgs-render --scene S.ply --trace T.trace --out-dir DIR [--every N]
//   catgs-render --scene S.ply --trace T.trace --video OUT.mp4 --width W --height H --fps F
//                [--crf 18] [--preset medium]                      (H.264 in MP4, server/encode/tour_video.h)
//   --lod-file F draws S's level of detail (a LOD file: catgs-scene lod) at --lod-error PX
//   (default RenderOptions::lod_error_px; 0 = full detail).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "common/image_io.h"
#include "scene/ply_io.h"
#include "scene/scene_cache.h"
#include "renderer/renderer.h"
#include "camera/trace.h"
#include "common/cli_args.h"
#ifdef CATGS_RENDER_VIDEO
#include "common/progress.h"
#include "encode/tour_video.h"
extern "C" {
#include <libavutil/log.h>
}
#endif

namespace {

const char* kUsage =
    "usage: catgs-render --scene FILE (--cameras CAMERAS.json [--view K | --all [--fps F]] |\n"
    "                    --trace FILE.trace) [--width W] [--height H]\n"
    "                    [--pipeline vanilla|exact] [--renderer cpu|cuda|auto]\n"
    "                    [--background R,G,B] [--lod-file F [--lod-error PX]]\n"
    "                    (--out FILE.png | --out-dir DIR [--every N] |\n"
    "                    --video FILE.mp4 [--fps F] [--crf C] [--preset P] [--max-frames N])\n"
    "  --video: the trace sampled on its clock at --fps (default 60) frames a second, H.264 in MP4\n"
    "  (x264 --preset, default medium, --crf, default 18), at --width x --height (default the\n"
    "  trace's size); at most --max-frames (default 216000: an hour at 60 fps); progress on stderr.\n";

// The cameras to render at width x height (0: their own size): a trace file, or views of an
// INRIA cameras.json (one --view, or --all interpolated at --fps, default `default_rate`).
catgs::Trace load_cameras(const catgs::tools::Args& args, int width, int height, double default_rate) {
  catgs::Trace trace;
  if (args.has("--trace")) {
    trace = catgs::read_trace(args.get("--trace"));
    if (trace.empty()) throw std::invalid_argument(args.get("--trace") + ": the trace has no cameras");
    if (width > 0 && height > 0)
      for (auto& tc : trace) tc.camera = tc.camera.rescaled(width, height);
    return trace;
  }
  const auto cams = catgs::load_inria_cameras(args.require("--cameras"), width, height);
  if (args.has("--all")) return catgs::interpolate_views(cams, args.get_double("--fps", default_rate), 1.0);
  const int k = args.get_int("--view", 0);
  if (k < 0 || k >= static_cast<int>(cams.size()))
    throw std::invalid_argument("--view " + std::to_string(k) + " outside 0.." + std::to_string(cams.size() - 1));
  trace.push_back({0.0, cams[static_cast<std::size_t>(k)]});
  return trace;
}

std::shared_ptr<catgs::Renderer> open_renderer(const catgs::tools::Args& args) {
  auto model = std::make_shared<catgs::GaussianModel>(
      args.has("--lod-file") ? catgs::load_lod_file(args.get("--lod-file"), args.require("--scene"))
                             : catgs::load_scene(args.require("--scene")));
  catgs::RenderOptions options;
  options.lod_error_px = static_cast<float>(args.get_double("--lod-error", options.lod_error_px));
  options.pipeline = catgs::parse_pipeline(args.get("--pipeline", "exact"));
  if (args.has("--background")) {
    float r, g, b;
    if (std::sscanf(args.get("--background").c_str(), "%f,%f,%f", &r, &g, &b) != 3)
      throw std::invalid_argument("--background wants R,G,B in [0, 1]");
    options.background = {r, g, b};
  }
  std::string why;
  std::shared_ptr<catgs::Renderer> renderer = catgs::make_renderer(args.get("--renderer", "cpu"), model, options, &why);
  std::cerr << "scene " << model->name << ": " << model->size() << " Gaussians, SH degree " << model->sh_degree << "; "
            << why << "\n";
  return renderer;
}

#ifdef CATGS_RENDER_VIDEO
constexpr int kMaxVideoFrames = 216000;  // an hour at 60 fps: --max-frames raises it

// --video: everything that can be checked (the trace, the size, the output file) is checked
// before the scene loads; an unfinished file is removed.
int render_video(const catgs::tools::Args& args) {
  av_log_set_level(AV_LOG_ERROR);  // x264's banner and statistics, the muxer's notes
  const int fps = args.get_int("--fps", 60);
  if (fps <= 0) throw std::invalid_argument("--fps must be positive");
  catgs::Trace cameras = load_cameras(args, 0, 0, fps);
  catgs::server::TourVideoOptions o;
  o.path = args.get("--video");
  o.width = args.get_int("--width", cameras.front().camera.width);
  o.height = args.get_int("--height", cameras.front().camera.height);
  o.fps = fps;
  o.crf = args.get_int("--crf", o.crf);
  o.preset = args.get("--preset", o.preset);
  // A path of absurd length (a typo in a time, a million poses) fails here, not out of memory.
  const double span_s = cameras.back().time_s - cameras.front().time_s;
  const long max_frames = args.get_int("--max-frames", kMaxVideoFrames);
  if (span_s * fps + 1.0 > static_cast<double>(max_frames))
    throw std::invalid_argument(args.get("--trace", "the path") + " lasts " + std::to_string(span_s) +
                                " s: " + std::to_string(static_cast<long long>(span_s * fps) + 1) + " frames at " +
                                std::to_string(fps) + " fps, more than --max-frames " + std::to_string(max_frames));
  catgs::Trace frames = catgs::resample_trace(cameras, fps);
  for (auto& tc : frames) tc.camera = tc.camera.rescaled(o.width, o.height);
  catgs::server::TourVideo video(o);
  const auto renderer = open_renderer(args);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    catgs::tools::Progress meter(stderr, isatty(STDERR_FILENO) == 1, static_cast<long>(frames.size()), "frames");
    video.render(*renderer, frames, [&meter](long done) { meter.update(done); });
  } catch (...) {
    std::error_code ec;  // the unfinished file, never a device such as /dev/full
    if (std::filesystem::is_regular_file(o.path, ec)) std::filesystem::remove(o.path, ec);
    throw;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cerr << "wrote " << o.path << ": " << frames.size() << " frames, " << o.width << "x" << o.height << " at " << fps
            << " fps (" << static_cast<double>(frames.size()) / fps << " s), " << std::filesystem::file_size(o.path)
            << " bytes, in " << seconds << " s\n";
  return 0;
}
#endif

int run(int argc, char** argv) {
  using catgs::tools::Args;
  const Args args(argc, argv,
                  {"--scene",  "--cameras",  "--view",     "--all!",       "--fps",      "--trace",     "--width",
                   "--height", "--pipeline", "--renderer", "--background", "--out",      "--out-dir",   "--every",
                   "--video",  "--crf",      "--preset",   "--max-frames", "--lod-file", "--lod-error", "--help!"});
  if (args.has("--help")) {
    std::cout << kUsage;
    return 0;
  }
  if (args.has("--video")) {
#ifdef CATGS_RENDER_VIDEO
    return render_video(args);
#else
    throw std::invalid_argument("--video: this catgs-render was built without the server's encoders (libavcodec)");
#endif
  }
  const auto renderer = open_renderer(args);
  const catgs::Trace trace = load_cameras(args, args.get_int("--width", 0), args.get_int("--height", 0), 30.0);

  catgs::Image image;
  if (args.has("--out")) {
    renderer->render(trace.front().camera, image);
    catgs::write_png(image, args.get("--out"));
    const auto& s = renderer->last_stats();
    std::cerr << "wrote " << args.get("--out") << " (" << image.width << "x" << image.height << ", " << s.total_ms
              << " ms, render list " << s.render_list_length << ")\n";
    return 0;
  }
  const std::string dir = args.require("--out-dir");
  std::filesystem::create_directories(dir);
  const int every = std::max(1, args.get_int("--every", 1));
  for (std::size_t i = 0; i < trace.size(); i += static_cast<std::size_t>(every)) {
    renderer->render(trace[i].camera, image);
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%05zu.png", i);
    catgs::write_png(image, dir + name);
  }
  std::cerr << "wrote " << (trace.size() + every - 1) / every << " frames to " << dir << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "catgs-render: " << e.what() << "\n" << kUsage;
    return 1;
  }
}
