// catgs-scene: scene utilities for measuring at scale (no GPU needed).
//
//   catgs-scene info    --scene S
//   catgs-scene compact --scene S --out O.compressed.ply [--check-views N] [--width W --height H]
//       Morton-sorts the Gaussians, writes SuperSplat compressed PLY, reads it back and (with
//       --check-views) prints the PSNR of CPU renders of the copy against the original.
//   catgs-scene convert --scene S --out O.(ply|compressed.ply|spz|catgs) [--spz-version 3|4]
//       Reads any scene format (ply_io.h) and writes INRIA PLY, SuperSplat compressed PLY (Morton
//       order), .spz (version 4 by default) or a compact scene (Morton order; a compact scene's
//       own order and levels; a compressed PLY's own order, so that its chunks keep their grids
//       and every code it held survives: compact_file_test CompressedPlySourceKeepsEveryCode) by
//       the output's extension.
//   catgs-scene tile    --scene S (--out city.ply | --out-compressed city.compressed.ply |
//                       --out-catgs city.catgs [--branching 8])
//                       [--radius-sq 4] [--spacing 1.2] [--scale 10] [--seed N] [--up X,Y,Z]
//                       [--no-sh-rotation] [--flyover-out F.trace] [--frames 600] [--rate 120]
//                       [--width 1920 --height 1080] [--fov 60] [--altitude 0.75] [--pitch 24]
//       The city recipe of docs/DESIGN.md "Measuring" (13 copies, x10, fly-over at 0.75
//       extents pitched 24 deg). --out-catgs: the city with its level of detail as a compact
//       scene (scene/compact_file.h), served alone.
//   catgs-scene trace   --scene S --cameras C.json --out T.trace [--scale 10] [--up X,Y,Z]
//                       [--rate 120] [--seconds-per-view 0.5] [--distance 0.6] [--frames N]
//                       [--width 1920 --height 1080]
//       A real camera path moved onto the scene (fit_trace_to_scene), 120 FPS.
//   catgs-scene interpolate --cameras C.json --out T.trace [--rate 120] [--seconds-per-view 0.5]
//                       [--width W --height H]
//       The cameras as they are, interpolated (interpolate_views): what catgs-loadgen and
//       catgs-bench replay for `cameras:C.json`, as a trace file (the web viewer's tour test
//       compares its own Catmull-Rom + slerp with it).
//   catgs-scene cache   --scene S [--out C] [--threads N]
//       Writes the scene cache (scene/scene_cache.h; default S.catgs-cache beside S): the next
//       load of S through the cache (catgs-server --scene-cache) copies it instead of parsing.
//   catgs-scene lod     --scene S --out O [--branching 8] [--threads N]
//       Builds the scene's level of detail (lod/lod_build.h) and writes it as a compact scene
//       (scene/compact_file.h, about 40 bytes a Gaussian): O ending in .catgs is served alone
//       (--scene O); any other name is a LOD file keyed to S (conventionally S.catgs-lod):
//       catgs-bench, catgs-render and catgs-server draw it with --scene S --lod-file O. A
//       compressed PLY S keeps its order: its chunks are the leaves and keep their codes.
//   catgs-scene load-bench --scenes A[,B...] [--threads N] [--repeat 3] [--no-reference]
//                       [--cache-dir D] [--json OUT] [--upload]
//       Load times, plain and cached, cold and warm page cache, with peak memory
//       (scene_tools/load_bench.h): a table and JSON.
//   catgs-scene probe   --scene S [--cameras C.json] [--frames 8] [--grid 8] [--width 1280 --height 720]
//                       [--json OUT]
//       Times the depth probe (cpu/pixel_depth.h, the server's DepthRequest): a grid x grid of
//       pixels on each of the first --frames cameras (without --cameras, one view of the robust
//       bounds from -z), without and with chunk culling (the server's); prints a table (ms per
//       probe, hits) and writes JSON.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <cstdio>
#include <iostream>

#include <nlohmann/json.hpp>

#include "common/image_io.h"
#include "cpu/pixel_depth.h"
#include "scene/ply_io.h"
#include "scene/compact_file.h"
#include "scene/scene_cache.h"
#include "scene/scene_peek.h"
#include "scene_tools/load_bench.h"
#include "scene/spz_file.h"
#include "renderer/renderer.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "lod/lod_build.h"
#include "scene/morton.h"
#include "scene/sh_rotation.h"
#include "camera/trace.h"
#include "common/cli_args.h"

namespace {

const char* kUsage =
    "usage: catgs-scene info --scene S\n"
    "       catgs-scene compact --scene S --out O.compressed.ply [--check-views N] [--width W --height H]\n"
    "                   [--scale 10] [--up X,Y,Z] [--png-prefix P]\n"
    "       catgs-scene convert --scene S --out O.(ply|compressed.ply|spz|catgs) [--spz-version 3|4]\n"
    "       catgs-scene tile --scene S (--out F.ply | --out-compressed F.compressed.ply |\n"
    "                   --out-catgs F.catgs [--branching 8] | --no-write)\n"
    "                   [--radius-sq 4] [--spacing 1.2] [--scale 10] [--seed N] [--up X,Y,Z]\n"
    "                   [--no-sh-rotation] [--flyover-out F.trace] [--frames 600] [--rate 120]\n"
    "                   [--width 1920 --height 1080] [--fov 60] [--altitude 0.75] [--pitch 24]\n"
    "       catgs-scene trace --scene S --cameras C.json --out T.trace [--scale 10] [--up X,Y,Z]\n"
    "                   [--rate 120] [--seconds-per-view 0.5] [--distance 0.6] [--frames N]\n"
    "                   [--width 1920 --height 1080]\n"
    "       catgs-scene cache --scene S [--out C] [--threads N]\n"
    "       catgs-scene lod --scene S --out O [--branching 8] [--threads N]\n"
    "       catgs-scene load-bench --scenes A[,B...] [--threads N] [--repeat 3] [--no-reference]\n"
    "                   [--cache-dir D] [--json OUT] [--upload]\n"
    "       catgs-scene probe --scene S [--cameras C.json] [--frames 8] [--grid 8] [--width 1280 --height 720]\n"
    "                   [--json OUT]\n";

glm::vec3 parse_vec3(const std::string& s) {
  glm::vec3 v;
  if (std::sscanf(s.c_str(), "%f,%f,%f", &v.x, &v.y, &v.z) != 3)
    throw std::invalid_argument("expected X,Y,Z, got '" + s + "'");
  return v;
}

void print_vec(const char* what, glm::vec3 v) { std::printf("%-16s (%.4g, %.4g, %.4g)\n", what, v.x, v.y, v.z); }

int info(const catgs::tools::Args& args) {
  const auto m = catgs::load_scene(args.require("--scene"));
  std::printf("scene %s: %zu Gaussians, SH degree %d\n", m.name.c_str(), m.size(), m.sh_degree);
  const auto b = m.bounds();
  const auto rb = catgs::robust_bounds(m);
  print_vec("bounds min", b.min);
  print_vec("bounds max", b.max);
  print_vec("robust min", rb.min);
  print_vec("robust max", rb.max);
  print_vec("robust extent", rb.extent());
  print_vec("estimated up", catgs::estimate_up(m));
  return 0;
}

int compact(const catgs::tools::Args& args) {
  const std::string in = args.require("--scene"), out = args.require("--out");
  const auto original_model = catgs::load_scene(in);
  const auto sorted = catgs::permuted(original_model, catgs::morton_order(original_model));
  catgs::write_compressed_ply(sorted, out);
  auto copy = std::make_shared<catgs::GaussianModel>(catgs::load_scene(out));
  std::printf("wrote %s: %zu Gaussians, SH degree %d\n", out.c_str(), copy->size(), copy->sh_degree);
  const int views = args.get_int("--check-views", 0);
  if (views <= 0) return 0;
  // Both are rendered at --scale (default 10: the scale of the benchmark scenes, docs/DESIGN.md
  // "Measuring"), so the near plane (0.2) cuts as it will there.
  const float scale = static_cast<float>(args.get_double("--scale", 10.0));
  catgs::GaussianModel m = original_model;
  catgs::scale_scene(m, scale);
  catgs::scale_scene(*copy, scale);
  catgs::GeneratorParams g;
  g.width = args.get_int("--width", 1280);
  g.height = args.get_int("--height", 720);
  g.up = args.has("--up") ? parse_vec3(args.get("--up")) : catgs::estimate_up(m);
  g.duration_s = 1.0;
  g.rate_hz = views;  // views + 1 samples over 360 degrees: the last repeats the first
  const auto rb = catgs::robust_bounds(m);
  const glm::vec3 e = rb.extent();
  const float radius = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const auto trace = catgs::make_orbit(rb, radius, 0.25f * radius, 360.0f, g);
  auto original = std::make_shared<catgs::GaussianModel>(m);
  catgs::RenderOptions o;
  auto ra = catgs::make_renderer("cpu", original, o);
  auto rc = catgs::make_renderer("cpu", copy, o);
  catgs::Image ia, ic;
  double sum = 0;
  for (int v = 0; v < views; ++v) {
    ra->render(trace[static_cast<std::size_t>(v)].camera, ia);
    rc->render(trace[static_cast<std::size_t>(v)].camera, ic);
    const double p = catgs::psnr_rgba8(ia, ic);
    if (args.has("--png-prefix")) {
      catgs::write_png(ia, args.get("--png-prefix") + std::to_string(v) + "_original.png");
      catgs::write_png(ic, args.get("--png-prefix") + std::to_string(v) + "_compact.png");
    }
    sum += p;
    std::printf("view %d: PSNR(compact vs original) = %.2f dB\n", v, p);
  }
  std::printf("mean PSNR(compact vs original) = %.2f dB over %d views at %dx%d\n", sum / views, views, g.width,
              g.height);
  return 0;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

int convert(const catgs::tools::Args& args) {
  const std::string out = args.require("--out");
  const auto m = catgs::load_scene(args.require("--scene"));
  if (ends_with(out, ".compressed.ply"))
    catgs::write_compressed_ply(catgs::permuted(m, catgs::morton_order(m)), out);
  else if (ends_with(out, ".catgs") &&
           (!m.lod.empty() || catgs::peek_scene(args.require("--scene")).format == "compressed_ply"))
    catgs::write_compact_scene(m, out);
  else if (ends_with(out, ".catgs"))
    catgs::write_compact_scene(catgs::permuted(m, catgs::morton_order(m)), out);
  else if (ends_with(out, ".spz"))
    catgs::write_spz(m, out, args.get_int("--spz-version", 4));
  else if (ends_with(out, ".ply"))
    catgs::write_inria_ply(m, out);
  else
    throw std::invalid_argument("--out must end in .ply, .compressed.ply, .spz or .catgs: '" + out + "'");
  std::printf("wrote %s: %zu Gaussians, SH degree %d\n", out.c_str(), m.size(), m.sh_degree);
  return 0;
}

// Builds `m`'s level of detail and writes it as a compact scene at `out`: keyed to `keyed_to`
// (a LOD file), or served alone when that is empty.
// A compressed PLY source keeps its order (catgs::LodBuildOptions::keep_order): its chunks stay
// the leaf chunks and keep their codes.
void write_lod_scene(const catgs::GaussianModel& m, const std::string& out, const std::string& keyed_to, int branching,
                     int threads = 0, bool keep_order = false) {
  catgs::LodBuildReport report;
  catgs::LodBuildOptions lod_options;
  lod_options.branching = branching;
  lod_options.keep_order = keep_order;
  const auto lod = catgs::build_lod(m, lod_options, &report);
  const auto t0 = std::chrono::steady_clock::now();
  catgs::write_compact_scene(lod, out, keyed_to, threads);
  const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(out, ec);
  std::printf("wrote %s: %zu Gaussians (%zu leaves%s), %.1f bytes a Gaussian, levels of", out.c_str(), lod.size(),
              m.size(), report.reordered ? ", Morton-sorted" : "",
              static_cast<double>(bytes) / static_cast<double>(lod.size()));
  for (std::size_t n : report.level_nodes) std::printf(" %zu", n);
  std::printf(" chunks; built in %.2f s, written in %.2f s\n", report.seconds, write_s);
}

int tile(const catgs::tools::Args& args) {
  const auto base = catgs::load_scene(args.require("--scene"));
  catgs::CityParams p;
  p.radius_sq = args.get_int("--radius-sq", p.radius_sq);
  p.spacing = static_cast<float>(args.get_double("--spacing", p.spacing));
  p.scale = static_cast<float>(args.get_double("--scale", p.scale));
  if (args.has("--seed")) p.seed = std::stoull(args.get("--seed"));
  if (args.has("--up")) p.up = parse_vec3(args.get("--up"));
  p.rotate_sh = !args.has("--no-sh-rotation");
  catgs::CityLayout layout;
  const auto city = catgs::tile_scene(base, p, &layout);
  std::printf("city %s: %zu copies x %zu = %zu Gaussians; extent %.4g, spacing %.4g\n", city.name.c_str(),
              layout.cells.size(), layout.gaussians_per_copy, city.size(), layout.extent, layout.spacing);
  print_vec("up", layout.up);
  print_vec("centre", layout.centre);
  for (std::size_t c = 0; c < layout.cells.size(); ++c)
    std::printf("  copy %2zu cell (%+d, %+d) yaw %6.1f deg\n", c, layout.cells[c].x, layout.cells[c].y,
                layout.yaw_deg[c]);
  if (args.has("--out")) catgs::write_inria_ply(city, args.get("--out"));
  if (args.has("--out-compressed"))
    catgs::write_compressed_ply(catgs::permuted(city, catgs::morton_order(city)), args.get("--out-compressed"));
  if (args.has("--out-catgs")) write_lod_scene(city, args.get("--out-catgs"), "", args.get_int("--branching", 8));
  if (args.has("--flyover-out")) {
    catgs::GeneratorParams g;
    g.width = args.get_int("--width", 1920);
    g.height = args.get_int("--height", 1080);
    g.rate_hz = args.get_double("--rate", 120.0);
    g.fov_deg = static_cast<float>(args.get_double("--fov", 60.0));
    g.duration_s = (args.get_int("--frames", 600) - 1) / g.rate_hz;
    catgs::FlyoverParams f;
    f.altitude = static_cast<float>(args.get_double("--altitude", f.altitude));
    f.pitch_deg = static_cast<float>(args.get_double("--pitch", f.pitch_deg));
    const auto trace = catgs::make_city_flyover(layout, f, g);
    catgs::write_trace(trace, args.get("--flyover-out"));
    std::printf("wrote %s: %zu cameras at %.0f Hz\n", args.get("--flyover-out").c_str(), trace.size(), g.rate_hz);
  }
  return 0;
}

int trace(const catgs::tools::Args& args) {
  auto scene = catgs::lod_leaves(catgs::load_scene(args.require("--scene")));  // a compact scene's leaves
  const float scale = static_cast<float>(args.get_double("--scale", 1.0));
  if (scale != 1.0f) catgs::scale_scene(scene, scale);
  const glm::vec3 up = args.has("--up") ? parse_vec3(args.get("--up")) : catgs::estimate_up(scene);
  const auto keys = catgs::load_inria_cameras(args.require("--cameras"));
  auto t = catgs::fit_trace_to_scene(keys, scene, up, static_cast<float>(args.get_double("--distance", 0.6)),
                                     args.get_double("--rate", 120.0), args.get_double("--seconds-per-view", 0.5),
                                     args.get_int("--width", 1920), args.get_int("--height", 1080));
  const int frames = args.get_int("--frames", 0);
  if (frames > 0 && static_cast<std::size_t>(frames) < t.size()) t.resize(static_cast<std::size_t>(frames));
  catgs::write_trace(t, args.require("--out"));
  std::printf("wrote %s: %zu cameras\n", args.get("--out").c_str(), t.size());
  return 0;
}

int interpolate(const catgs::tools::Args& args) {
  const auto keys =
      catgs::load_inria_cameras(args.require("--cameras"), args.get_int("--width", 0), args.get_int("--height", 0));
  const auto t =
      catgs::interpolate_views(keys, args.get_double("--rate", 120.0), args.get_double("--seconds-per-view", 0.5));
  catgs::write_trace(t, args.require("--out"));
  std::printf("wrote %s: %zu cameras\n", args.get("--out").c_str(), t.size());
  return 0;
}

int cache(const catgs::tools::Args& args) {
  const std::string scene = args.require("--scene");
  const std::string out = args.get("--out", catgs::scene_cache_path(scene));
  const int threads = args.get_int("--threads", 0);
  const auto m = catgs::load_scene(scene, catgs::LoadOptions{threads, false});
  catgs::write_scene_cache(m, scene, out, threads);
  std::printf("wrote %s: %zu Gaussians, SH degree %d\n", out.c_str(), m.size(), m.sh_degree);
  return 0;
}

int lod(const catgs::tools::Args& args) {
  const std::string scene = args.require("--scene"), out = args.require("--out");
  const int threads = args.get_int("--threads", 0);
  const auto m = catgs::load_scene(scene, catgs::LoadOptions{threads, false});
  // F.catgs: the scene served alone; any other name: a LOD file keyed to the scene.
  write_lod_scene(m, out, ends_with(out, ".catgs") ? "" : scene, args.get_int("--branching", 8), threads,
                  catgs::peek_scene(scene).format == "compressed_ply");
  return 0;
}

int load_bench(const catgs::tools::Args& args) {
  catgs::tools::LoadBenchOptions o;
  std::string list = args.require("--scenes");
  for (std::size_t at = 0; at <= list.size();) {
    const std::size_t comma = std::min(list.find(',', at), list.size());
    if (comma > at) o.scenes.push_back(list.substr(at, comma - at));
    at = comma + 1;
  }
  o.threads = args.get_int("--threads", 0);
  o.repeat = args.get_int("--repeat", 3);
  o.reference = !args.has("--no-reference");
  o.upload = args.has("--upload");
  o.cache_dir = args.get("--cache-dir");
  o.json_path = args.get("--json");
  return catgs::tools::run_load_bench(o);
}

// The views `probe` times: the first `frames` cameras of --cameras, or one view of the robust
// bounds' centre from -z at their diagonal (60 degrees vertical).
std::vector<catgs::Camera> probe_views(const catgs::tools::Args& args, const catgs::GaussianModel& m, int w, int h) {
  std::vector<catgs::Camera> views;
  if (args.has("--cameras")) {
    views = catgs::load_inria_cameras(args.get("--cameras"), w, h);
    views.resize(std::min<std::size_t>(views.size(), static_cast<std::size_t>(args.get_int("--frames", 8))));
  } else {
    const catgs::Bounds b = catgs::robust_bounds(m);
    const glm::vec3 eye = b.center() - glm::vec3(0.0f, 0.0f, glm::length(b.extent()));
    views.push_back(catgs::Camera::from_pose(eye, glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, w, h));
  }
  return views;
}

// Times `views` x grid^2 probes, with or without chunk culling: one row of the table and the JSON.
nlohmann::json time_probes(const catgs::GaussianModel& m, const std::vector<catgs::Camera>& views, int grid,
                           const std::vector<catgs::fm::ChunkBounds>* chunks) {
  std::vector<double> ms;
  int hits = 0;
  for (const catgs::Camera& cam : views)
    for (int j = 0; j < grid; ++j)
      for (int i = 0; i < grid; ++i) {
        const double x = (i + 0.5) * cam.width / grid, y = (j + 0.5) * cam.height / grid;
        const auto t0 = std::chrono::steady_clock::now();
        const catgs::cpu::PixelDepth d = catgs::cpu::probe_pixel_depth(m, cam, x, y, chunks);
        ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        hits += d.hit ? 1 : 0;
      }
  if (ms.empty()) throw std::invalid_argument("no views to probe");
  std::sort(ms.begin(), ms.end());
  const auto pct = [&ms](double q) { return ms[static_cast<std::size_t>(q * static_cast<double>(ms.size() - 1))]; };
  double sum = 0;
  for (double v : ms) sum += v;
  const double mean = sum / static_cast<double>(ms.size());
  const char* culling = chunks ? "chunks" : "none";
  std::printf("%-16s %10zu %-8s %6zu %7zu %6d %9.3f %9.3f %9.3f %9.3f\n", m.name.c_str(), m.size(), culling,
              views.size(), ms.size(), hits, mean, pct(0.5), pct(0.95), ms.back());
  return {{"culling", culling},    {"probes", ms.size()}, {"hits", hits},       {"mean_ms", mean},
          {"median_ms", pct(0.5)}, {"p95_ms", pct(0.95)}, {"max_ms", ms.back()}};
}

int probe(const catgs::tools::Args& args) {
  const auto m = catgs::load_scene(args.require("--scene"));
  const int w = args.get_int("--width", 1280), h = args.get_int("--height", 720), grid = args.get_int("--grid", 8);
  const auto views = probe_views(args, m, w, h);
  const auto chunks = chunk_bounds_of(m);
  std::printf("%-16s %10s %-8s %6s %7s %6s %9s %9s %9s %9s\n", "scene", "gaussians", "culling", "views", "probes",
              "hits", "mean_ms", "median_ms", "p95_ms", "max_ms");
  nlohmann::json j = {{"scene", m.name}, {"gaussians", m.size()}, {"views", views.size()},
                      {"width", w},      {"height", h},           {"rows", nlohmann::json::array()}};
  j["rows"].push_back(time_probes(m, views, grid, nullptr));
  j["rows"].push_back(time_probes(m, views, grid, &chunks));
  if (args.has("--json")) std::ofstream(args.get("--json")) << j.dump(1) << "\n";
  return 0;
}

int run(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help") {
    std::cout << kUsage;
    return argc < 2 ? 1 : 0;
  }
  const std::string cmd = argv[1];
  const catgs::tools::Args args(
      argc - 1, argv + 1,
      {"--scene",           "--out",         "--out-compressed",   "--no-write!",     "--check-views", "--width",
       "--height",          "--radius-sq",   "--spacing",          "--scale",         "--seed",        "--up",
       "--no-sh-rotation!", "--flyover-out", "--frames",           "--rate",          "--fov",         "--altitude",
       "--pitch",           "--cameras",     "--seconds-per-view", "--distance",      "--png-prefix",  "--spz-version",
       "--threads",         "--scenes",      "--repeat",           "--no-reference!", "--cache-dir",   "--json",
       "--upload!",         "--grid",        "--out-catgs",        "--branching"});
  if (cmd == "info") return info(args);
  if (cmd == "compact") return compact(args);
  if (cmd == "convert") return convert(args);
  if (cmd == "tile") return tile(args);
  if (cmd == "trace") return trace(args);
  if (cmd == "interpolate") return interpolate(args);
  if (cmd == "cache") return cache(args);
  if (cmd == "lod") return lod(args);
  if (cmd == "load-bench") return load_bench(args);
  if (cmd == "probe") return probe(args);
  throw std::invalid_argument("unknown command '" + cmd + "'");
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "catgs-scene: " << e.what() << "\n" << kUsage;
    return 1;
  }
}
