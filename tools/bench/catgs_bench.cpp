// catgs-bench: replays a trace through the render pipelines and reports frame times (a benchmark:
// it reports, it never fails on time).
//
//   catgs-bench --scene S [--city] [--scale F] --trace T --width 1920 --height 1080
//               --pipeline vanilla,exact[,exact-warp][,catgs[-nocache|-nosplit|-nocull|-wN|-pN|-qN|-mN|-aN|-fN|-bN|-sN][-tsort]][,exact-dsort]
//               [--frames N] [--warmup N] [--json OUT.json] [--snapshot-dir DIR] [--up X,Y,Z] [--renderer cuda|cpu]
//               [--quality-every K]
//
// catgs variants (paper Tables 1/3 ablations and the supplementary's window table): catgs-nocache
// (--no-cache: every frame a key frame), catgs-nosplit (--no-split), catgs-wN (W_initial = N),
// catgs-pN (the motion predictor fits its velocities over the last N ms instead of 50), catgs-qN
// (its acceleration over the last N ms instead of 100; catgs-q0: constant velocity), catgs-nocull
// (CUDA: the rasterizer blends every entry of the trail list, CudaRenderer::set_tile_culling),
// catgs-mN (trails widened by N% of each Gaussian's screen motion over the window,
// SpeculationParams::trail_motion_margin), catgs-aN (and by N pixels, trail_margin_px), catgs-fN
// (a key frame whose window comes out below N renders in full, SpeculationParams::min_window),
// catgs-bN (after a group that served fewer than 2 sub-frames, N frames in full,
// SpeculationParams::backoff_frames; N = 0 turns the backoff off), catgs-sN (task splitting's
// slices at least N entries long, SpeculationParams::min_slice_entries).
// The CUDA render list's sort (CudaRenderer::set_depth_first_sort; the same list either way): a
// catgs name ending in -tsort (catgs-tsort, catgs-w2-tsort) sorts it in one radix sort of
// [tile | depth] keys instead of depth first; exact-dsort sorts exact's depth first.
// catgs frames are posed at the trace's 120 FPS clock (render_device_at), so the motion predictor
// sees the real timing. With --quality-every K (CUDA; default 1, 0 = off), every K-th frame of each
// catgs variant is compared, after its timing, with a full `exact` render of the same pose by a
// second renderer: sub-frames give the image quality (PSNR over 8-bit RGB, max abs error of the
// float image), key frames the render-list growth (catgs key list / exact list, same pose).
//
// --renderer cpu (the default in a build without CUDA) times the CPU reference with the steady
// clock around render_at() (pose in, 8-bit image in host memory out); catgs runs there only.
//
// --city builds DESIGN.md's city in memory from S (13 copies on a diamond grid, x10 scale; with
// --radius-sq, --spacing, --seed to vary it); otherwise S is scaled by --scale (default 1).
// exact-warp is the exact pipeline with the rasterizer's optional per-warp skip (same image).
// T: "flyover" (the city fly-over: 0.75 extents up, pitched down 24 deg), "real:CAMERAS.json" (a
// real camera path moved onto the scene, tools/scene_tools/city.h), "cameras:CAMERAS.json" (the scene's own
// cameras, interpolated as they are), "orbit", or a catgs-trace file. Traces
// are generated at 120 FPS; the first --warmup frames are rendered untimed, then --frames frames
// (default 600) are timed.
//
// Each frame is timed with CUDA events on the renderer's stream around render_device(): pose in,
// image in device memory out (pre-processing, the one host readback, key emission, sort, tile
// ranges, rasterization), no disk I/O, no download. All pipelines share one DeviceScene and run in
// this process on the same frames, one after the other.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numeric>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#if CATGS_HAVE_CUDA
#include <cuda_runtime.h>

#include "cuda/cuda_renderer.h"
#endif
#include "common/image_io.h"
#include "scene/ply_io.h"
#include "renderer/renderer.h"
#include "scene/scene_bounds.h"
#include "scene_tools/city.h"
#include "camera/trace.h"
#include "common/cli_args.h"

namespace {

const char* kUsage =
    "usage: catgs-bench --scene S [--city [--radius-sq 4] [--spacing 1.2] [--seed N]] [--scale F]\n"
    "                   --trace flyover|orbit|real:C.json|cameras:C.json|FILE.trace [--width 1920]\n"
    "                   [--height 1080] [--pipeline vanilla,exact[,exact-warp]] [--frames 600]\n"
    "                   [--warmup 30]\n"
    "                   [--json OUT.json] [--snapshot-dir DIR] [--up X,Y,Z]\n"
    "                   [--seconds-per-view 0.5] [--distance 0.6] [--renderer cuda|cpu]\n";

#if CATGS_HAVE_CUDA
void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess)
    throw std::runtime_error(std::string(what) + ": " + cudaGetErrorName(e) + ": " + cudaGetErrorString(e));
}
#endif

struct Summary {
  double mean = 0, median = 0, p99 = 0, min = 0, max = 0;
};
Summary summarize(std::vector<double> v) {
  Summary s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.mean = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  s.median = v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  s.p99 = v[std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(0.99 * static_cast<double>(v.size()))) - 1)];
  s.min = v.front();
  s.max = v.back();
  return s;
}

struct PipelineResult {
  std::string name;
  std::vector<double> frame_ms, pre, keys, sort, ranges, raster, list, visible, heaviest;
  std::vector<double> key_ms, sub_ms, window;  // catgs: key vs sub-frame times, W per key frame
  // catgs: key frames drawn after a rejected sub-frame, and key frames without a window (W = 0).
  std::vector<double> rejected_ms, full_ms;
  struct Groups {
    std::size_t count = 0, served = 0, rejected = 0;  // groups, sub-frames served, ended by a rejection
  };
  std::map<int, Groups> groups;  // catgs: by W, the groups that closed during the timed frames
  int open_window = 0;           // the open group's W (0: none), and its sub-frames so far
  std::size_t open_served = 0;
  std::vector<double> key_stage[6], sub_stage[6];  // catgs: pre, keys, sort, ranges, raster, merge
  std::vector<double> sub_psnr, sub_max_abs, list_growth;  // catgs vs exact, same pose (--quality-every)
  std::size_t subframes_inf = 0;  // sub-frames identical to the full render (PSNR +inf)
  std::size_t peak_buffer_bytes = 0, device_used_bytes = 0, allocations_timed = 0;
  int syncs = 0;
};

glm::vec3 parse_vec3(const std::string& s) {
  glm::vec3 v;
  if (std::sscanf(s.c_str(), "%f,%f,%f", &v.x, &v.y, &v.z) != 3)
    throw std::invalid_argument("expected X,Y,Z, got '" + s + "'");
  return v;
}

int run(int argc, char** argv) {
  using catgs::tools::Args;
  const Args args(argc, argv, {"--scene", "--city!", "--radius-sq", "--spacing", "--seed", "--scale",
                               "--trace", "--width", "--height", "--pipeline", "--frames", "--warmup",
                               "--json", "--snapshot-dir", "--up", "--seconds-per-view", "--distance",
                               "--renderer", "--quality-every", "--help!"});
  if (args.has("--help")) {
    std::cout << kUsage;
    return 0;
  }
#if CATGS_HAVE_CUDA
  const bool on_gpu = args.get("--renderer", "cuda") == "cuda";
#else
  const bool on_gpu = false;
  if (args.get("--renderer", "cpu") != "cpu") throw std::invalid_argument("built without CUDA: --renderer cpu only");
#endif
  std::string gpu = "none (CPU reference, " + std::to_string(std::thread::hardware_concurrency()) + " threads)";
#if CATGS_HAVE_CUDA
  if (on_gpu) {
    std::string why;
    if (!catgs::cuda::device_usable(&why)) throw std::runtime_error("no usable CUDA device: " + why);
    gpu = catgs::cuda::device_description();
  }
#endif
  const int width = args.get_int("--width", 1920), height = args.get_int("--height", 1080);
  const int frames = args.get_int("--frames", 600), warmup = args.get_int("--warmup", 30);
  const std::string trace_spec = args.require("--trace");

  // Scene.
  const auto t_load = std::chrono::steady_clock::now();
  catgs::GaussianModel model = catgs::load_scene(args.require("--scene"));
  catgs::CityLayout layout;
  const bool city = args.has("--city");
  glm::vec3 up = args.has("--up") ? parse_vec3(args.get("--up")) : glm::vec3(0.0f);
  if (city) {
    catgs::CityParams p;
    p.radius_sq = args.get_int("--radius-sq", p.radius_sq);
    p.spacing = static_cast<float>(args.get_double("--spacing", p.spacing));
    p.scale = static_cast<float>(args.get_double("--scale", p.scale));
    if (args.has("--seed")) p.seed = std::stoull(args.get("--seed"));
    p.up = up;
    model = catgs::tile_scene(model, p, &layout);
    up = layout.up;
  } else {
    const float s = static_cast<float>(args.get_double("--scale", 1.0));
    if (s != 1.0f) catgs::scale_scene(model, s);
    if (glm::length(up) == 0.0f) up = catgs::estimate_up(model);
  }
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();

  // Trace at 120 FPS.
  catgs::GeneratorParams g;
  g.width = width;
  g.height = height;
  g.rate_hz = 120.0;
  g.duration_s = (warmup + frames - 1) / g.rate_hz;
  g.up = up;
  catgs::Trace trace;
  if (trace_spec == "flyover") {
    if (!city) throw std::invalid_argument("--trace flyover needs --city");
    trace = catgs::make_city_flyover(layout, catgs::FlyoverParams{}, g);
  } else if (trace_spec == "orbit") {
    const auto rb = catgs::robust_bounds(model);
    const glm::vec3 e = rb.extent();
    const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
    trace = catgs::make_orbit(rb, r, 0.3f * r, 100.0f, g);
  } else if (trace_spec.rfind("cameras:", 0) == 0) {
    // The scene's own cameras (same world frame), interpolated to 120 FPS as they are.
    trace = catgs::interpolate_views(catgs::load_inria_cameras(trace_spec.substr(8), width, height), 120.0,
                                     args.get_double("--seconds-per-view", 0.5));
  } else if (trace_spec.rfind("real:", 0) == 0) {
    const auto keys = catgs::load_inria_cameras(trace_spec.substr(5));
    trace = catgs::fit_trace_to_scene(keys, model, up,
                                      static_cast<float>(args.get_double("--distance", 0.6)), 120.0,
                                      args.get_double("--seconds-per-view", 0.5), width, height);
  } else {
    trace = catgs::read_trace(trace_spec);
    for (auto& tc : trace) tc.camera = tc.camera.rescaled(width, height);
  }
  if (trace.empty()) throw std::runtime_error("empty trace");
  auto camera_at = [&](int k) { return trace[static_cast<std::size_t>(k) % trace.size()].camera; };

  // "exact-warp": the exact pipeline with the rasterizer's optional per-warp skip.
  struct Variant {
    std::string name;
    catgs::Pipeline pipeline;
    bool warp_cull;
    catgs::SpeculationParams speculation;
    bool tile_cull = true;  // catgs-nocull: off
    bool depth_first = false;  // catgs: on unless -tsort; exact: off unless -dsort
  };
  std::vector<Variant> pipelines;
  {
    std::stringstream ss(args.get("--pipeline", "vanilla,exact"));
    for (std::string name; std::getline(ss, name, ',');) {
      const std::string full_name = name;
      auto strip = [&name](const std::string& suffix) {
        const bool has = name.size() > suffix.size() &&
                         name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
        if (has) name.erase(name.size() - suffix.size());
        return has;
      };
      const bool single_sort = strip("-tsort"), depth_first = strip("-dsort");
      Variant v{name, catgs::Pipeline::catgs, false, {}};
      if (name == "exact-warp") v = {name, catgs::Pipeline::exact, true, {}};
      else if (name == "catgs-nocache") v.speculation.frustum_and_sort_cache = false;
      else if (name == "catgs-nosplit") v.speculation.task_splitting = false;
      else if (name == "catgs-nocull") v.tile_cull = false;
      else if (name.rfind("catgs-w", 0) == 0) v.speculation.initial_window = std::stoi(name.substr(7));
      else if (name.rfind("catgs-p", 0) == 0) v.speculation.predictor_window_s = std::stoi(name.substr(7)) / 1000.0;
      else if (name.rfind("catgs-q", 0) == 0)
        v.speculation.predictor_acceleration_window_s = std::stoi(name.substr(7)) / 1000.0;
      else if (name.rfind("catgs-m", 0) == 0) v.speculation.trail_motion_margin = static_cast<float>(std::stoi(name.substr(7))) / 100.0f;
      else if (name.rfind("catgs-a", 0) == 0) v.speculation.trail_margin_px = std::stof(name.substr(7));
      else if (name.rfind("catgs-f", 0) == 0) v.speculation.min_window = std::stoi(name.substr(7));
      else if (name.rfind("catgs-b", 0) == 0) v.speculation.backoff_frames = std::stoi(name.substr(7));
      else if (name.rfind("catgs-s", 0) == 0) v.speculation.min_slice_entries = std::stoi(name.substr(7));
      else v.pipeline = catgs::parse_pipeline(name);
      v.name = full_name;
      v.depth_first = depth_first || (v.pipeline == catgs::Pipeline::catgs && !single_sort);
      pipelines.push_back(v);
    }
  }
  [[maybe_unused]] const int quality_every = args.get_int("--quality-every", 1);  // CUDA only

  std::vector<PipelineResult> results;
  auto record = [](PipelineResult& res, double ms, const catgs::FrameStats& s) {
    res.frame_ms.push_back(ms);
    res.pre.push_back(s.preprocess_ms);
    res.keys.push_back(s.keys_ms);
    res.sort.push_back(s.sort_ms);
    res.ranges.push_back(s.ranges_ms);
    res.raster.push_back(s.rasterize_ms);
    res.list.push_back(static_cast<double>(s.render_list_length));
    res.visible.push_back(static_cast<double>(s.visible));
    (s.key_frame ? res.key_ms : res.sub_ms).push_back(ms);
    if (s.key_frame) {
      res.window.push_back(s.window);
      if (s.subframe_rejected) res.rejected_ms.push_back(ms);
      if (s.window == 0) res.full_ms.push_back(ms);
      if (res.open_window > 0) {  // the key frame closes the open group
        auto& group = res.groups[res.open_window];
        ++group.count;
        group.served += res.open_served;
        group.rejected += s.subframe_rejected ? 1 : 0;
      }
      res.open_window = s.window;
      res.open_served = 0;
    } else {
      ++res.open_served;
    }
    const double stage[6] = {s.preprocess_ms, s.keys_ms, s.sort_ms, s.ranges_ms, s.rasterize_ms, s.merge_ms};
    for (int k = 0; k < 6; ++k) (s.key_frame ? res.key_stage : res.sub_stage)[k].push_back(stage[k]);
  };
  std::string scene_name = model.name;
  std::size_t scene_size = model.size(), scene_bytes = 0;
  const int scene_sh = model.sh_degree;
#if CATGS_HAVE_CUDA
  if (on_gpu) {
  const std::size_t used_before_scene = catgs::cuda::device_memory_used();
  const auto scene = catgs::cuda::DeviceScene::upload(model);
  scene_bytes = scene->bytes();
  std::fprintf(stderr, "GPU: %s\nscene %s: %zu Gaussians (SH %d, %.0f MiB on device), built in %.1f s; "
               "trace %s: %zu cameras, %d warm-up + %d timed frames at %dx%d\n",
               gpu.c_str(), model.name.c_str(), model.size(), model.sh_degree,
               static_cast<double>(scene->bytes()) / (1 << 20), load_s, trace_spec.c_str(),
               trace.size(), warmup, frames, width, height);
  model = catgs::GaussianModel{};  // the host copy is no longer needed

  catgs::RenderOptions exact_options;
  exact_options.pipeline = catgs::Pipeline::exact;
  catgs::cuda::CudaRenderer reference(scene, exact_options);  // --quality-every's full renders
  catgs::Image image, full;
  for (const Variant& variant : pipelines) {
    catgs::RenderOptions o;
    o.pipeline = variant.pipeline;
    o.speculation = variant.speculation;
    const bool catgs_variant = variant.pipeline == catgs::Pipeline::catgs;
    catgs::cuda::CudaRenderer r(scene, o);
    r.set_warp_culling(variant.warp_cull);
    r.set_tile_culling(variant.tile_cull);
    r.set_depth_first_sort(variant.depth_first);
    PipelineResult res;
    res.name = variant.name;
    cudaEvent_t start, end;
    check(cudaEventCreate(&start), "cudaEventCreate");
    check(cudaEventCreate(&end), "cudaEventCreate");
    const double dt = 1.0 / 120.0;  // the trace's clock
    for (int k = 0; k < warmup; ++k) {
      r.render_device_at(camera_at(k), k * dt);
      (void)r.last_stats();
    }
    const std::size_t allocs_before = r.allocation_count();
    for (int k = 0; k < frames; ++k) {
      const catgs::Camera cam = camera_at(warmup + k);
      check(cudaEventRecord(start, r.stream()), "cudaEventRecord");
      const catgs::cuda::DeviceFrame frame = r.render_device_at(cam, (warmup + k) * dt);
      check(cudaEventRecord(end, r.stream()), "cudaEventRecord");
      check(cudaEventSynchronize(end), "cudaEventSynchronize");
      float ms = 0;
      check(cudaEventElapsedTime(&ms, start, end), "cudaEventElapsedTime");
      const catgs::FrameStats stats = r.last_stats();
      record(res, ms, stats);
      res.heaviest.push_back(static_cast<double>(r.heaviest_tile_entries()));  // after timing
      if (catgs_variant && quality_every > 0 && k % quality_every == 0) {  // after timing too
        reference.render(cam, full);
        if (stats.key_frame) {
          res.list_growth.push_back(static_cast<double>(stats.render_list_length) /
                                    std::max<double>(1.0, static_cast<double>(reference.last_stats().render_list_length)));
        } else {
          const std::size_t pixels = static_cast<std::size_t>(frame.width) * frame.height;
          image.width = frame.width;
          image.height = frame.height;
          image.rgb.resize(pixels * 3);
          image.rgba8.resize(pixels * 4);
          check(cudaMemcpy(image.rgb.data(), frame.rgb, pixels * 3 * sizeof(float), cudaMemcpyDeviceToHost),
                "cudaMemcpy");
          check(cudaMemcpy(image.rgba8.data(), frame.rgba8, pixels * 4, cudaMemcpyDeviceToHost), "cudaMemcpy");
          const double p = catgs::psnr_rgba8(image, full);
          double max_abs = 0.0;
          for (std::size_t i = 0; i < image.rgb.size(); ++i)
            max_abs = std::max(max_abs, static_cast<double>(std::fabs(image.rgb[i] - full.rgb[i])));
          if (std::isinf(p)) ++res.subframes_inf;
          else res.sub_psnr.push_back(p);
          res.sub_max_abs.push_back(max_abs);
        }
      }
    }
    res.allocations_timed = r.allocation_count() - allocs_before;
    res.peak_buffer_bytes = r.peak_buffer_bytes();
    res.device_used_bytes = catgs::cuda::device_memory_used() - used_before_scene;
    res.syncs = r.syncs_last_frame();
    if (args.has("--snapshot-dir") && !variant.warp_cull) {  // exact-warp's image is exact's
      std::filesystem::create_directories(args.get("--snapshot-dir"));
      catgs::Image img;
      r.render(camera_at(warmup + frames / 2), img);
      catgs::write_png(img, args.get("--snapshot-dir") + "/" + scene->name() + "_" +
                                res.name + ".png");
    }
    cudaEventDestroy(start);
    cudaEventDestroy(end);
    results.push_back(std::move(res));
  }
  }
#endif
  if (!on_gpu) {
    std::fprintf(stderr, "CPU reference: %s\nscene %s: %zu Gaussians (SH %d), built in %.1f s; trace %s: "
                 "%zu cameras, %d warm-up + %d timed frames at %dx%d\n", gpu.c_str(), model.name.c_str(),
                 model.size(), model.sh_degree, load_s, trace_spec.c_str(), trace.size(), warmup, frames,
                 width, height);
    const auto shared = std::make_shared<const catgs::GaussianModel>(std::move(model));
    for (const Variant& variant : pipelines) {
      if (variant.warp_cull || !variant.tile_cull || !variant.depth_first)
        throw std::invalid_argument(variant.name + " is a CUDA variant");
      catgs::RenderOptions o;
      o.pipeline = variant.pipeline;
      o.speculation = variant.speculation;
      auto r = catgs::make_renderer("cpu", shared, o);
      PipelineResult res;
      res.name = variant.name;
      catgs::Image img;
      const double dt = 1.0 / 120.0;
      for (int k = 0; k < warmup; ++k) r->render_at(camera_at(k), k * dt, img);
      for (int k = 0; k < frames; ++k) {
        const auto t0 = std::chrono::steady_clock::now();
        r->render_at(camera_at(warmup + k), (warmup + k) * dt, img);
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        record(res, ms, r->last_stats());
      }
      if (args.has("--snapshot-dir")) {
        std::filesystem::create_directories(args.get("--snapshot-dir"));
        catgs::write_png(img, args.get("--snapshot-dir") + "/" + scene_name + "_cpu_" + res.name + ".png");
      }
      results.push_back(std::move(res));
    }
  }

  // Table.
  std::printf("\nGPU: %s\nscene: %s, %zu Gaussians; trace: %s; %dx%d; %d timed frames (after %d warm-up)\n",
              gpu.c_str(), scene_name.c_str(), scene_size, trace_spec.c_str(), width, height,
              frames, warmup);
  std::printf("%-10s %8s %8s %8s %8s | %7s %7s %7s %7s %7s | %12s %12s %10s %9s | %9s %9s %5s\n",
              "pipeline", "mean ms", "median", "p99", "FPS", "pre", "keys", "sort", "ranges",
              "raster", "list mean", "list max", "visible", "max tile", "buf MiB", "dev MiB", "syncs");
  nlohmann::json j;
  j["gpu"] = gpu;
  j["renderer"] = on_gpu ? "cuda" : "cpu";
  j["scene"] = scene_name;
  j["gaussians"] = scene_size;
  j["sh_degree"] = scene_sh;
  j["scene_device_bytes"] = scene_bytes;
  j["trace"] = trace_spec;
  j["width"] = width;
  j["height"] = height;
  j["frames"] = frames;
  j["warmup"] = warmup;
  j["timing"] = on_gpu ? "CUDA events around render_device() on the renderer's stream; pose in, image in device memory out"
                       : "steady clock around render_at(); pose in, 8-bit image in host memory out";
  for (const auto& r : results) {
    const Summary f = summarize(r.frame_ms), L = summarize(r.list);
    auto mean = [](const std::vector<double>& v) { return summarize(v).mean; };
    std::printf("%-10s %8.3f %8.3f %8.3f %8.1f | %7.3f %7.3f %7.3f %7.3f %7.3f | %12.0f %12.0f %10.0f %9.0f | %9.1f %9.1f %5d\n",
                r.name.c_str(), f.mean, f.median, f.p99, 1000.0 / f.mean, mean(r.pre), mean(r.keys),
                mean(r.sort), mean(r.ranges), mean(r.raster), L.mean, L.max, mean(r.visible),
                mean(r.heaviest),
                static_cast<double>(r.peak_buffer_bytes) / (1 << 20),
                static_cast<double>(r.device_used_bytes) / (1 << 20), r.syncs);
    nlohmann::json p;
    p["pipeline"] = r.name;
    p["frame_ms"] = {{"mean", f.mean}, {"median", f.median}, {"p99", f.p99}, {"min", f.min}, {"max", f.max}};
    p["fps"] = 1000.0 / f.mean;
    p["stages_ms_mean"] = {{"preprocess", mean(r.pre)}, {"keys", mean(r.keys)}, {"sort", mean(r.sort)},
                           {"tile_ranges", mean(r.ranges)}, {"rasterize", mean(r.raster)}};
    p["render_list"] = {{"mean", L.mean}, {"median", L.median}, {"min", L.min}, {"max", L.max}};
    p["visible_mean"] = mean(r.visible);
    p["heaviest_tile_entries"] = {{"mean", mean(r.heaviest)}, {"max", summarize(r.heaviest).max}};
    p["peak_buffer_bytes"] = r.peak_buffer_bytes;
    p["device_memory_used_bytes"] = r.device_used_bytes;
    p["scene_plus_peak_buffers_bytes"] = r.peak_buffer_bytes + scene_bytes;
    if (r.name.rfind("catgs", 0) == 0) {  // catgs: speculation
      const Summary k = summarize(r.key_ms), sub = summarize(r.sub_ms);
      auto stage_json = [&](const std::vector<double>* st) {
        return nlohmann::json{{"preprocess", mean(st[0])}, {"keys", mean(st[1])}, {"sort", mean(st[2])},
                              {"tile_ranges", mean(st[3])}, {"rasterize", mean(st[4])}, {"merge", mean(st[5])}};
      };
      p["key_frames"] = {{"count", r.key_ms.size()}, {"mean_ms", k.mean}, {"median_ms", k.median},
                         {"stages_ms_mean", stage_json(r.key_stage)}};
      p["sub_frames"] = {{"count", r.sub_ms.size()}, {"mean_ms", sub.mean}, {"median_ms", sub.median},
                         {"stages_ms_mean", stage_json(r.sub_stage)}};
      p["sub_over_key_cost"] = r.sub_ms.empty() ? 0.0 : sub.mean / k.mean;
      p["window_mean"] = summarize(r.window).mean;
      p["rejected_subframes"] = {{"count", r.rejected_ms.size()},
                                 {"key_frame_mean_ms", summarize(r.rejected_ms).mean}};
      p["full_frames"] = {{"count", r.full_ms.size()}, {"mean_ms", summarize(r.full_ms).mean}};
      for (const auto& [w, group] : r.groups)
        p["groups_by_window"][std::to_string(w)] = {{"groups", group.count},
                                                    {"sub_frames_served", group.served},
                                                    {"ended_by_rejection", group.rejected}};
      std::map<int, int> windows;
      for (double w : r.window) ++windows[static_cast<int>(w)];
      for (const auto& [w, count] : windows) p["window_histogram"][std::to_string(w)] = count;
      std::printf("%-10s key frames %zu (%.3f ms mean), sub-frames %zu (%.3f ms mean, %.0f%% of a key frame), "
                  "mean window %.2f\n", r.name.c_str(), r.key_ms.size(), k.mean, r.sub_ms.size(), sub.mean,
                  r.sub_ms.empty() ? 0.0 : 100.0 * sub.mean / k.mean, summarize(r.window).mean);
      std::printf("%-10s   %zu rejected sub-frames (their key frames %.3f ms mean); %zu full frames (W = 0, "
                  "%.3f ms mean); groups by W (groups, sub-frames served, ended by rejection):",
                  r.name.c_str(), r.rejected_ms.size(), summarize(r.rejected_ms).mean, r.full_ms.size(),
                  summarize(r.full_ms).mean);
      for (const auto& [w, group] : r.groups)
        std::printf(" W%d %zu/%zu/%zu", w, group.count, group.served, group.rejected);
      std::printf("\n");
      std::printf("%-10s   key stages ms: pre %.3f keys %.3f sort %.3f ranges %.3f raster %.3f merge %.3f | "
                  "sub stages ms: pre %.3f raster %.3f merge %.3f\n", r.name.c_str(), mean(r.key_stage[0]),
                  mean(r.key_stage[1]), mean(r.key_stage[2]), mean(r.key_stage[3]), mean(r.key_stage[4]),
                  mean(r.key_stage[5]), mean(r.sub_stage[0]), mean(r.sub_stage[4]), mean(r.sub_stage[5]));
      if (!r.sub_psnr.empty() || r.subframes_inf > 0 || !r.list_growth.empty()) {
        const Summary q = summarize(r.sub_psnr), grow = summarize(r.list_growth), e = summarize(r.sub_max_abs);
        p["subframe_quality_vs_full_render"] = {
            {"compared", r.sub_psnr.size() + r.subframes_inf}, {"identical", r.subframes_inf},
            {"psnr_db_mean_finite", q.mean}, {"psnr_db_min", q.min}, {"max_abs_error", e.max}};
        p["key_list_growth_vs_exact"] = {{"compared", r.list_growth.size()}, {"mean", grow.mean}, {"max", grow.max}};
        std::printf("%-10s   sub-frames vs full render: %zu compared (%zu identical), PSNR mean %.2f dB "
                    "(finite ones), min %.2f dB, max abs %.3g; key list / exact list: mean %.4f, max %.4f\n",
                    r.name.c_str(), r.sub_psnr.size() + r.subframes_inf, r.subframes_inf, q.mean, q.min, e.max,
                    grow.mean, grow.max);
      }
    }
    p["host_device_syncs_per_frame"] = r.syncs;
    p["allocations_during_timed_frames"] = r.allocations_timed;
    p["per_frame_ms"] = r.frame_ms;
    p["per_frame_render_list"] = r.list;
    j["pipelines"].push_back(p);
  }
  auto find = [&](const char* name) -> const PipelineResult* {
    for (const auto& r : results)
      if (r.name == name) return &r;
    return nullptr;
  };
  if (const auto *v = find("vanilla"), *e = find("exact"); v && e) {
    const double fps_ratio = summarize(v->frame_ms).mean / summarize(e->frame_ms).mean;
    const double list_ratio = summarize(v->list).mean / summarize(e->list).mean;
    std::printf("exact / vanilla: FPS x%.2f, render list %.2fx shorter\n", fps_ratio, list_ratio);
    j["exact_over_vanilla"] = {{"fps_ratio", fps_ratio}, {"render_list_ratio", list_ratio}};
  }
  for (const auto& r : results) {  // every catgs variant against the full-frame pipelines of this run
    if (r.name.rfind("catgs", 0) != 0) continue;
    const double t = summarize(r.frame_ms).mean;
    for (const char* base : {"vanilla", "exact"}) {
      if (const auto* b = find(base)) {
        const double ratio = summarize(b->frame_ms).mean / t;
        std::printf("%s / %s: FPS x%.2f\n", r.name.c_str(), base, ratio);
        j["fps_ratios"][r.name + "_over_" + base] = ratio;
      }
    }
  }
  if (args.has("--json")) {
    std::ofstream out(args.get("--json"));
    out << j.dump(1) << "\n";
    if (!out) throw std::runtime_error(args.get("--json") + ": write failed");
  }
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
