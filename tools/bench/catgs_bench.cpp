// catgs-bench: replays a trace through the render pipelines and reports frame times (a benchmark:
// it reports, it never fails on time).
//
//   catgs-bench --scene S [--city] [--scale F] --trace T --width 1920 --height 1080
//               --pipeline V[,V...] [--frames N] [--warmup N] [--json OUT.json]
//               [--snapshot-dir DIR] [--up X,Y,Z] [--renderer cuda|cpu] [--quality-every K]
//               [--lod [--branching 8] | --lod-file F] [--lod-error PX[,PX...]] [--aa-reference F]
//               [--compact]
//
// Variants V (bench/variants.h; `catgs-bench --help` lists the settings): vanilla, exact, or
// catgs optionally followed by SpeculationParams settings in braces, catgs{window=2,backoff=0},
// the settings of apply_speculation_settings (speculation/settings.h). The paper's ablations are
// presets: catgs-nocache = catgs{cache=off} (every frame a key frame), catgs-nosplit =
// catgs{split=off}, catgs-wN = catgs{window=N} (the supplementary's window table); a preset takes
// braces too (catgs-w2{backoff=0}). Commas inside braces belong to the braces (quote the list
// in a shell); the table and the JSON name each variant as written; an unknown name or setting
// is an error. Default: vanilla,exact.
// catgs frames are posed at the trace's 120 FPS clock (render_device_at), so the motion predictor
// sees the real timing; --pose-rate HZ stamps the same frames at HZ instead (the same motion a
// frame on a slower clock, as a session sending HZ poses a second). With --quality-every K (CUDA; default 1, 0 = off), every K-th frame of each
// catgs variant is compared, after its timing, with a full `exact` render of the same pose by a
// second renderer: sub-frames give the image quality (PSNR over 8-bit RGB, max abs error of the
// float image), key frames the render-list growth (catgs key list / exact list, same pose).
//
// --renderer cpu (the default in a build without CUDA) times the CPU reference with the steady
// clock around render_at() (pose in, 8-bit image in host memory out), with the same variants.
//
// --city builds the city of docs/DESIGN.md "Measuring" in memory from S (13 copies on a diamond
// grid, x10 scale; with --radius-sq, --spacing, --seed to vary it); otherwise S is scaled by
// --scale (default 1).
// Level of detail (forward_model/lod.h): --lod builds it in memory after that
// (lod/lod_build.h; its build time and level sizes are printed and in the JSON);
// --lod-file F reads S's LOD file (catgs-scene lod). Every variant draws the cut at --lod-error
// PX (default RenderOptions::lod_error_px; 0 = full detail; a list PX,PX... runs every variant
// at each bound, named VARIANT@PX), and with --quality-every K every K-th frame of every variant,
// on both cores, is compared with the full-detail exact render. --aa-reference F (F >= 2) also
// compares those frames, and the full-detail render of the same pose, with an anti-aliased
// reference: full detail rendered F times larger each way and box-filtered down (a merged
// Gaussian averages texture that full detail samples at one point a pixel; this says how much of
// the LOD's loss against full detail is that). A compact scene (--scene F.catgs) brings its own
// level of detail (--lod then builds nothing). --compact quantizes the scene as the compact scene
// keeps it (scene/compact_file.h quantize_compact, after --lod) and draws both references from
// the float scene, so the yardstick says what the quantization costs (issue 74).
// Issue 72's measurement of where a frame's list goes: the JSON's entries_behind_opaque_mean
// (exact-occlusion: entries at or behind their tile's opaque point, forward_model/occlusion.h),
// and with --count-changes (--renderer cpu; slow) entries_changing_pixels_mean and
// gaussians_changing_pixels_mean (entries blended at a pixel while its transmittance was above
// 1/255, and their Gaussians; such frames are drawn without task splitting), and what this frame's
// own per-pixel map could drop at best (cpu::count_hidden): gaussians_preprocessed_mean (of the
// cut's chunks in view), gaussians_in_hidden_chunks_mean, gaussians_in_hidden_groups_mean (runs of
// 32), gaussians_hidden_alone_mean and
// entries_hidden_pixels_mean. Every variant: chunks_preprocessed_mean (FrameStats).
// T: "flyover" (the city fly-over: 0.75 extents up, pitched down 24 deg), "centre" (a slow pass
// over the city's middle copy, 0.4 extents up, pitched down 70 deg: only the centre copies are in
// view, however many the city has), "real:CAMERAS.json" (a
// real camera path moved onto the scene, tools/scene_tools/city.h), "cameras:CAMERAS.json" (the scene's own
// cameras, interpolated as they are), "orbit", or a catgs-trace file. Traces
// are generated at 120 FPS; the first --warmup frames (default 30) are rendered untimed, then
// --frames frames (default 600) are timed.
//
// Each frame is timed with CUDA events on the renderer's stream around render_device(): pose in,
// image in device memory out (pre-processing, the one host readback, key emission, sort, tile
// ranges, rasterization), no disk I/O, no download. All pipelines share one DeviceScene and run in
// this process on the same frames, one after the other (bench/timing_loop.h); bench/report.h
// prints the table and writes the JSON.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#if CATGS_HAVE_CUDA
#include "cuda/cuda_renderer.h"
#endif
#include "bench/report.h"
#include "bench/timing_loop.h"
#include "bench/variants.h"
#include "camera/camera.h"
#include "camera/trace.h"
#include "common/cli_args.h"
#include "scene/ply_io.h"
#include "scene/scene_bounds.h"
#include "scene/scene_cache.h"
#include "lod/lod_build.h"
#include "scene/compact_file.h"
#include "scene_tools/city.h"

namespace {

using catgs::bench::BenchContext;
using catgs::bench::PipelineResult;
using catgs::bench::TimingPlan;
using catgs::bench::Variant;
using catgs::tools::Args;

const char* kUsage =
    "usage: catgs-bench --scene S [--city [--radius-sq 4] [--spacing 1.2] [--seed N]] [--scale F]\n"
    "                   --trace flyover|centre|orbit|real:C.json|cameras:C.json|FILE.trace\n"
    "                   [--width 1920]\n"
    "                   [--height 1080] [--pipeline V[,V...]] [--frames 600] [--warmup 30]\n"
    "                   [--quality-every 1] [--json OUT.json] [--snapshot-dir DIR] [--up X,Y,Z]\n"
    "                   [--seconds-per-view 0.5] [--distance 0.6] [--renderer cuda|cpu] [--help]\n"
    "                   [--lod [--branching 8] | --lod-file F] [--lod-error PX[,PX...]] [--aa-reference F]\n"
    "                   [--pose-rate 120] [--compact]\n"
    "       V: a pipeline variant, e.g. catgs{window=2,backoff=0} (default: vanilla,exact; --help\n"
    "          lists the variants and their settings)\n";

glm::vec3 parse_vec3(const std::string& s) {
  glm::vec3 v;
  if (std::sscanf(s.c_str(), "%f,%f,%f", &v.x, &v.y, &v.z) != 3)
    throw std::invalid_argument("expected X,Y,Z, got '" + s + "'");
  return v;
}

// The scene as loaded (or built: --city) and its up direction.
struct BenchScene {
  catgs::GaussianModel model;
  catgs::CityLayout layout;
  bool city = false;
  glm::vec3 up{0.0f};
  double load_s = 0;          // loading and building
  catgs::LodBuildReport lod;  // --lod
  // --compact: the float scene, kept to draw the references the quantized one is compared with.
  std::shared_ptr<const catgs::GaussianModel> reference;
};

BenchScene load_bench_scene(const Args& args) {
  const auto t_load = std::chrono::steady_clock::now();
  BenchScene s;
  if (args.has("--lod-file") && (args.has("--lod") || args.has("--city") || args.has("--scale")))
    throw std::invalid_argument("--lod-file is the scene as it is: no --lod, --city or --scale with it");
  s.model = args.has("--lod-file") ? catgs::load_lod_file(args.get("--lod-file"), args.require("--scene"))
                                   : catgs::load_scene(args.require("--scene"));
  s.city = args.has("--city");
  s.up = args.has("--up") ? parse_vec3(args.get("--up")) : glm::vec3(0.0f);
  if (s.city) {
    catgs::CityParams p;
    p.radius_sq = args.get_int("--radius-sq", p.radius_sq);
    p.spacing = static_cast<float>(args.get_double("--spacing", p.spacing));
    p.scale = static_cast<float>(args.get_double("--scale", p.scale));
    if (args.has("--seed")) p.seed = std::stoull(args.get("--seed"));
    p.up = s.up;
    s.model = catgs::tile_scene(s.model, p, &s.layout);
    s.up = s.layout.up;
  } else {
    const float scale = static_cast<float>(args.get_double("--scale", 1.0));
    if (scale != 1.0f) catgs::scale_scene(s.model, scale);
    if (glm::length(s.up) == 0.0f) s.up = catgs::estimate_up(s.model);
  }
  if (args.has("--lod") && !s.model.lod.empty()) {
    std::fprintf(stderr, "LOD from the compact scene: %zu Gaussians\n", s.model.size());
  } else if (args.has("--lod")) {
    catgs::LodBuildOptions lod_options;
    lod_options.branching = args.get_int("--branching", 8);
    s.model = catgs::build_lod(s.model, lod_options, &s.lod);
    std::fprintf(stderr, "LOD built in %.2f s: %zu Gaussians, chunks per level:", s.lod.seconds, s.model.size());
    for (std::size_t n : s.lod.level_nodes) std::fprintf(stderr, " %zu", n);
    std::fprintf(stderr, "\n");
  }
  if (args.has("--compact")) {  // quantized as the compact scene keeps it (compact_file.h)
    s.reference = std::make_shared<const catgs::GaussianModel>(s.model);
    catgs::quantize_compact(s.model);
  }
  s.load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();
  return s;
}

// --trace at 120 FPS, long enough for `frames` frames where it is generated.
catgs::Trace make_bench_trace(const Args& args, const BenchScene& s, int width, int height, int frames) {
  const std::string spec = args.require("--trace");
  catgs::GeneratorParams g;
  g.width = width;
  g.height = height;
  g.rate_hz = 120.0;
  g.duration_s = (frames - 1) / g.rate_hz;
  g.up = s.up;
  catgs::Trace trace;
  if (spec == "flyover") {
    if (!s.city) throw std::invalid_argument("--trace flyover needs --city");
    trace = catgs::make_city_flyover(s.layout, catgs::FlyoverParams{}, g);
  } else if (spec == "centre") {
    if (!s.city) throw std::invalid_argument("--trace centre needs --city");
    catgs::FlyoverParams centre;
    centre.altitude = 0.4f;
    centre.pitch_deg = 70.0f;
    centre.start_cells = -0.25f;
    centre.end_cells = 0.25f;
    trace = catgs::make_city_flyover(s.layout, centre, g);
  } else if (spec == "orbit") {
    const auto rb = catgs::robust_bounds(s.model);
    const glm::vec3 e = rb.extent();
    const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
    trace = catgs::make_orbit(rb, r, 0.3f * r, 100.0f, g);
  } else if (spec.rfind("cameras:", 0) == 0) {
    // The scene's own cameras (same world frame), interpolated to 120 FPS as they are.
    trace = catgs::interpolate_views(catgs::load_inria_cameras(spec.substr(8), width, height), 120.0,
                                     args.get_double("--seconds-per-view", 0.5));
  } else if (spec.rfind("real:", 0) == 0) {
    const auto keys = catgs::load_inria_cameras(spec.substr(5));
    trace = catgs::fit_trace_to_scene(keys, s.model, s.up, static_cast<float>(args.get_double("--distance", 0.6)),
                                      120.0, args.get_double("--seconds-per-view", 0.5), width, height);
  } else {
    trace = catgs::read_trace(spec);
    for (auto& tc : trace) tc.camera = tc.camera.rescaled(width, height);
  }
  if (trace.empty()) throw std::runtime_error("empty trace");
  return trace;
}

// --lod-error PX[,PX...]: the LOD bounds to run every variant at ("default": RenderOptions's).
std::vector<float> lod_bounds(const Args& args) {
  std::vector<float> out;
  const std::string list = args.get("--lod-error", std::to_string(catgs::RenderOptions{}.lod_error_px));
  for (std::size_t at = 0; at <= list.size();) {
    const std::size_t comma = std::min(list.find(',', at), list.size());
    std::string item = list.substr(at, comma - at);
    if (item == "default") item = std::to_string(catgs::RenderOptions{}.lod_error_px);
    std::size_t used = 0;
    float v = -1.0f;
    try {
      v = std::stof(item, &used);
    } catch (const std::exception&) {}
    if (used != item.size() || item.empty() || !(v >= 0.0f))
      throw std::invalid_argument("--lod-error: '" + item + "' is not a bound in pixels >= 0");
    out.push_back(v);
    at = comma + 1;
  }
  return out;
}

// With several LOD bounds, a variant's result is named VARIANT@PX.
PipelineResult named_at(PipelineResult r, float bound, std::size_t bounds) {
  if (bounds > 1) {
    char at[32];
    std::snprintf(at, sizeof at, "@%g", bound);
    r.name += at;
  }
  return r;
}

// --renderer: true for the CUDA core (the default where it is built). Throws when it is asked for
// and missing or unusable.
bool use_cuda(const Args& args) {
#if CATGS_HAVE_CUDA
  if (args.get("--renderer", "cuda") != "cuda") return false;
  std::string why;
  if (!catgs::cuda::device_usable(&why)) throw std::runtime_error("no usable CUDA device: " + why);
  return true;
#else
  if (args.get("--renderer", "cpu") != "cpu") throw std::invalid_argument("built without CUDA: --renderer cpu only");
  return false;
#endif
}

#if CATGS_HAVE_CUDA
std::vector<PipelineResult> run_on_cuda(BenchScene& s, const std::vector<Variant>& variants, TimingPlan plan,
                                        const std::vector<float>& bounds, BenchContext& c) {
  const std::size_t used_before_scene = catgs::cuda::device_memory_used();
  const auto scene = catgs::cuda::DeviceScene::upload(s.model);
  c.scene_device_bytes = scene->bytes();
  const auto reference = s.reference ? catgs::cuda::DeviceScene::upload(*s.reference) : nullptr;
  s.reference.reset();
  std::fprintf(stderr,
               "GPU: %s\nscene %s: %zu Gaussians (SH %d, %.0f MiB on device), built in %.1f s; "
               "trace %s: %zu cameras, %d warm-up + %d timed frames at %dx%d\n",
               c.gpu.c_str(), c.scene.c_str(), c.gaussians, c.sh_degree,
               static_cast<double>(scene->bytes()) / (1 << 20), s.load_s, c.trace.c_str(), plan.trace->size(), c.warmup,
               c.frames, c.width, c.height);
  s.model = catgs::GaussianModel{};  // the host copy is no longer needed
  std::vector<PipelineResult> results;
  for (float bound : bounds) {
    plan.lod_error_px = bound;
    for (PipelineResult& r : catgs::bench::time_on_cuda(scene, variants, plan, used_before_scene, reference))
      results.push_back(named_at(std::move(r), bound, bounds.size()));
  }
  return results;
}
#endif

std::vector<PipelineResult> run_on_cpu(BenchScene& s, const std::vector<Variant>& variants, TimingPlan plan,
                                       const std::vector<float>& bounds, const BenchContext& c) {
  std::fprintf(stderr,
               "CPU reference: %s\nscene %s: %zu Gaussians (SH %d), built in %.1f s; trace %s: "
               "%zu cameras, %d warm-up + %d timed frames at %dx%d\n",
               c.gpu.c_str(), c.scene.c_str(), c.gaussians, c.sh_degree, s.load_s, c.trace.c_str(), plan.trace->size(),
               c.warmup, c.frames, c.width, c.height);
  const auto shared = std::make_shared<const catgs::GaussianModel>(std::move(s.model));
  std::vector<PipelineResult> results;
  for (float bound : bounds) {
    plan.lod_error_px = bound;
    for (PipelineResult& r : catgs::bench::time_on_cpu(shared, variants, plan, s.reference))
      results.push_back(named_at(std::move(r), bound, bounds.size()));
  }
  return results;
}

int run(int argc, char** argv) {
  const Args args(argc, argv,
                  {"--scene",
                   "--city!",
                   "--radius-sq",
                   "--spacing",
                   "--seed",
                   "--scale",
                   "--trace",
                   "--width",
                   "--height",
                   "--pipeline",
                   "--frames",
                   "--warmup",
                   "--json",
                   "--snapshot-dir",
                   "--up",
                   "--seconds-per-view",
                   "--distance",
                   "--renderer",
                   "--quality-every",
                   "--lod!",
                   "--branching",
                   "--lod-file",
                   "--lod-error",
                   "--aa-reference",
                   "--pose-rate",
                   "--count-changes!",
                   "--compact!",
                   "--help!"});
  if (args.has("--help")) {
    std::cout << kUsage << "\n" << catgs::bench::variant_syntax();
    return 0;
  }
  const std::vector<Variant> variants = catgs::bench::parse_variants(args.get("--pipeline", "vanilla,exact"));
  BenchContext c;
  c.on_gpu = use_cuda(args);
  c.gpu = "none (CPU reference, " + std::to_string(std::thread::hardware_concurrency()) + " threads)";
#if CATGS_HAVE_CUDA
  if (c.on_gpu) c.gpu = catgs::cuda::device_description();
#endif
  c.width = args.get_int("--width", 1920);
  c.height = args.get_int("--height", 1080);
  c.frames = args.get_int("--frames", 600);
  c.warmup = args.get_int("--warmup", 30);
  c.trace = args.require("--trace");

  BenchScene s = load_bench_scene(args);
  c.scene = s.model.name;
  c.gaussians = s.model.size();
  c.sh_degree = s.model.sh_degree;
  c.lod = !s.model.lod.empty();
  const std::vector<float> bounds = lod_bounds(args);
  c.lod_error_px = bounds.front();
  c.lod_build_s = s.lod.seconds;
  c.lod_levels = s.lod.level_nodes;
  const catgs::Trace trace = make_bench_trace(args, s, c.width, c.height, c.warmup + c.frames);
  TimingPlan plan;
  plan.trace = &trace;
  plan.warmup = c.warmup;
  plan.frames = c.frames;
  plan.quality_every = args.get_int("--quality-every", 1);
  plan.pose_rate_hz = c.pose_rate_hz = args.get_double("--pose-rate", 120.0);
  if (!(plan.pose_rate_hz > 0.0) || !std::isfinite(plan.pose_rate_hz))
    throw std::invalid_argument("--pose-rate must be a positive number of poses a second");
  plan.lod = c.lod;
  plan.lod_error_px = c.lod_error_px;
  plan.count_changes = args.has("--count-changes");
  plan.aa_factor = args.get_int("--aa-reference", 0);
  if (plan.aa_factor != 0 && (plan.aa_factor < 2 || !plan.lod))
    throw std::invalid_argument("--aa-reference F needs F >= 2 and a scene with LOD (--lod or --lod-file)");
  // The reference is F times the frame each way: refused here, before timing, where it would be
  // over the renderers' largest side (and F x width could overflow an int).
  if (plan.aa_factor > catgs::kMaxImageSide / std::max({c.width, c.height, 1}))
    throw std::invalid_argument("--aa-reference " + std::to_string(plan.aa_factor) + ": the reference would be over " +
                                std::to_string(catgs::kMaxImageSide) + " pixels a side at " + std::to_string(c.width) +
                                "x" + std::to_string(c.height));
  plan.snapshot_dir = args.get("--snapshot-dir");

  std::vector<PipelineResult> results;
#if CATGS_HAVE_CUDA
  if (c.on_gpu) results = run_on_cuda(s, variants, plan, bounds, c);
#endif
  if (!c.on_gpu) results = run_on_cpu(s, variants, plan, bounds, c);
  const nlohmann::json j = catgs::bench::report(c, results);
  if (args.has("--json")) catgs::bench::write_json(j, args.get("--json"));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "catgs-bench: " << e.what() << "\n" << kUsage;
    return 1;
  }
}
