#include "bench/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <numeric>
#include <stdexcept>

namespace catgs::bench {

namespace {

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
double mean(const std::vector<double>& v) { return summarize(v).mean; }
// The finite values of v (an identical image has PSNR +inf).
std::vector<double> finite(const std::vector<double>& v) {
  std::vector<double> out;
  std::copy_if(v.begin(), v.end(), std::back_inserter(out), [](double x) { return std::isfinite(x); });
  return out;
}

nlohmann::json context_json(const BenchContext& c) {
  nlohmann::json j;
  j["gpu"] = c.gpu;
  j["renderer"] = c.on_gpu ? "cuda" : "cpu";
  j["scene"] = c.scene;
  j["gaussians"] = c.gaussians;
  j["sh_degree"] = c.sh_degree;
  j["scene_device_bytes"] = c.scene_device_bytes;
  j["trace"] = c.trace;
  j["width"] = c.width;
  j["height"] = c.height;
  j["frames"] = c.frames;
  j["warmup"] = c.warmup;
  j["pose_rate_hz"] = c.pose_rate_hz;
  if (c.lod) j["lod"] = {{"error_px", c.lod_error_px}, {"build_s", c.lod_build_s}, {"level_chunks", c.lod_levels}};
  j["timing"] = c.on_gpu
                    ? "CUDA events around render_device() on the renderer's stream; pose in, image in device memory out"
                    : "steady clock around render_at(); pose in, 8-bit image in host memory out";
  return j;
}

void print_header(const BenchContext& c) {
  std::printf("\nGPU: %s\nscene: %s, %zu Gaussians; trace: %s; %dx%d; %d timed frames (after %d warm-up)\n",
              c.gpu.c_str(), c.scene.c_str(), c.gaussians, c.trace.c_str(), c.width, c.height, c.frames, c.warmup);
  std::printf("%-10s %8s %8s %8s %8s | %7s %7s %7s %7s %7s | %12s %12s %10s %9s | %9s %9s %5s\n", "pipeline", "mean ms",
              "median", "p99", "FPS", "pre", "keys", "sort", "ranges", "raster", "list mean", "list max", "visible",
              "max tile", "buf MiB", "dev MiB", "syncs");
}

// The variant's row of the table, and its JSON apart from the speculation.
nlohmann::json table_row(const PipelineResult& r, std::size_t scene_bytes) {
  const Summary f = summarize(r.frame_ms), L = summarize(r.list);
  std::printf(
      "%-10s %8.3f %8.3f %8.3f %8.1f | %7.3f %7.3f %7.3f %7.3f %7.3f | %12.0f %12.0f %10.0f %9.0f | %9.1f %9.1f %5d\n",
      r.name.c_str(), f.mean, f.median, f.p99, 1000.0 / f.mean, mean(r.pre), mean(r.keys), mean(r.sort), mean(r.ranges),
      mean(r.raster), L.mean, L.max, mean(r.visible), mean(r.heaviest),
      static_cast<double>(r.peak_buffer_bytes) / (1 << 20), static_cast<double>(r.device_used_bytes) / (1 << 20),
      r.syncs);
  nlohmann::json p;
  p["pipeline"] = r.name;
  p["frame_ms"] = {{"mean", f.mean}, {"median", f.median}, {"p99", f.p99}, {"min", f.min}, {"max", f.max}};
  p["fps"] = 1000.0 / f.mean;
  p["stages_ms_mean"] = {{"preprocess", mean(r.pre)},
                         {"keys", mean(r.keys)},
                         {"sort", mean(r.sort)},
                         {"tile_ranges", mean(r.ranges)},
                         {"rasterize", mean(r.raster)}};
  p["render_list"] = {{"mean", L.mean}, {"median", L.median}, {"min", L.min}, {"max", L.max}};
  p["visible_mean"] = mean(r.visible);
  p["chunks_preprocessed_mean"] = mean(r.chunks);
  p["entries_behind_opaque_mean"] = mean(r.behind_opaque);
  p["entries_changing_pixels_mean"] = mean(r.changing_entries);
  p["gaussians_changing_pixels_mean"] = mean(r.changing_gaussians);
  p["gaussians_preprocessed_mean"] = mean(r.preprocessed);
  p["gaussians_in_hidden_chunks_mean"] = mean(r.hidden_chunks);
  p["gaussians_in_hidden_groups_mean"] = mean(r.hidden_groups);
  p["gaussians_hidden_alone_mean"] = mean(r.hidden_alone);
  p["entries_hidden_pixels_mean"] = mean(r.entries_hidden_px);
  p["heaviest_tile_entries"] = {{"mean", mean(r.heaviest)}, {"max", summarize(r.heaviest).max}};
  p["peak_buffer_bytes"] = r.peak_buffer_bytes;
  p["device_memory_used_bytes"] = r.device_used_bytes;
  p["scene_plus_peak_buffers_bytes"] = r.peak_buffer_bytes + scene_bytes;
  p["host_device_syncs_per_frame"] = r.syncs;
  p["allocations_during_timed_frames"] = r.allocations_timed;
  p["per_frame_ms"] = r.frame_ms;
  p["per_frame_render_list"] = r.list;
  return p;
}

nlohmann::json stage_json(const std::vector<double>* st) {
  return nlohmann::json{{"preprocess", mean(st[0])},  {"keys", mean(st[1])},      {"sort", mean(st[2])},
                        {"tile_ranges", mean(st[3])}, {"rasterize", mean(st[4])}, {"merge", mean(st[5])}};
}

// catgs: key vs sub-frames, rejections, full frames, groups and windows by W.
void speculation_report(const PipelineResult& r, nlohmann::json& p) {
  const Summary k = summarize(r.key_ms), sub = summarize(r.sub_ms);
  p["key_frames"] = {{"count", r.key_ms.size()},
                     {"mean_ms", k.mean},
                     {"median_ms", k.median},
                     {"stages_ms_mean", stage_json(r.key_stage)}};
  p["sub_frames"] = {{"count", r.sub_ms.size()},
                     {"mean_ms", sub.mean},
                     {"median_ms", sub.median},
                     {"stages_ms_mean", stage_json(r.sub_stage)}};
  p["sub_over_key_cost"] = r.sub_ms.empty() ? 0.0 : sub.mean / k.mean;
  p["window_mean"] = mean(r.window);
  p["rejected_subframes"] = {{"count", r.rejected_ms.size()}, {"key_frame_mean_ms", mean(r.rejected_ms)}};
  p["full_frames"] = {{"count", r.full_ms.size()}, {"mean_ms", mean(r.full_ms)}};
  for (const auto& [w, group] : r.groups)
    p["groups_by_window"][std::to_string(w)] = {
        {"groups", group.count}, {"sub_frames_served", group.served}, {"ended_by_rejection", group.rejected}};
  std::map<int, int> windows;
  for (double w : r.window) ++windows[static_cast<int>(w)];
  for (const auto& [w, count] : windows) p["window_histogram"][std::to_string(w)] = count;
  std::printf(
      "%-10s key frames %zu (%.3f ms mean), sub-frames %zu (%.3f ms mean, %.0f%% of a key frame), "
      "mean window %.2f\n",
      r.name.c_str(), r.key_ms.size(), k.mean, r.sub_ms.size(), sub.mean,
      r.sub_ms.empty() ? 0.0 : 100.0 * sub.mean / k.mean, mean(r.window));
  std::printf(
      "%-10s   %zu rejected sub-frames (their key frames %.3f ms mean); %zu full frames (W = 0, "
      "%.3f ms mean); groups by W (groups, sub-frames served, ended by rejection):",
      r.name.c_str(), r.rejected_ms.size(), mean(r.rejected_ms), r.full_ms.size(), mean(r.full_ms));
  for (const auto& [w, group] : r.groups) std::printf(" W%d %zu/%zu/%zu", w, group.count, group.served, group.rejected);
  std::printf("\n");
  std::printf(
      "%-10s   key stages ms: pre %.3f keys %.3f sort %.3f ranges %.3f raster %.3f merge %.3f | "
      "sub stages ms: pre %.3f raster %.3f merge %.3f\n",
      r.name.c_str(), mean(r.key_stage[0]), mean(r.key_stage[1]), mean(r.key_stage[2]), mean(r.key_stage[3]),
      mean(r.key_stage[4]), mean(r.key_stage[5]), mean(r.sub_stage[0]), mean(r.sub_stage[4]), mean(r.sub_stage[5]));
}

// catgs with --quality-every: sub-frames and key lists against the full exact render.
void quality_report(const PipelineResult& r, nlohmann::json& p) {
  if (r.sub_psnr.empty() && r.subframes_inf == 0 && r.list_growth.empty()) return;
  const Summary q = summarize(r.sub_psnr), grow = summarize(r.list_growth), e = summarize(r.sub_max_abs);
  p["subframe_quality_vs_full_render"] = {{"compared", r.sub_psnr.size() + r.subframes_inf},
                                          {"identical", r.subframes_inf},
                                          {"psnr_db_mean_finite", q.mean},
                                          {"psnr_db_min", q.min},
                                          {"max_abs_error", e.max}};
  p["key_list_growth_vs_exact"] = {{"compared", r.list_growth.size()}, {"mean", grow.mean}, {"max", grow.max}};
  std::printf(
      "%-10s   sub-frames vs full render: %zu compared (%zu identical), PSNR mean %.2f dB "
      "(finite ones), min %.2f dB, max abs %.3g; key list / exact list: mean %.4f, max %.4f\n",
      r.name.c_str(), r.sub_psnr.size() + r.subframes_inf, r.subframes_inf, q.mean, q.min, e.max, grow.mean, grow.max);
}

// A scene with LOD and --quality-every: every compared frame against the full-detail render.
void lod_quality_report(const PipelineResult& r, nlohmann::json& p) {
  if (r.lod_psnr.empty() && r.lod_identical == 0) return;
  const Summary q = summarize(r.lod_psnr);
  p["lod_quality_vs_full_detail"] = {{"compared", r.lod_psnr.size() + r.lod_identical},
                                     {"identical", r.lod_identical},
                                     {"psnr_db_mean_finite", q.mean},
                                     {"psnr_db_min", q.min}};
  std::printf(
      "%-10s   LOD frames vs full detail: %zu compared (%zu identical), PSNR mean %.2f dB (finite ones), "
      "min %.2f dB\n",
      r.name.c_str(), r.lod_psnr.size() + r.lod_identical, r.lod_identical, q.mean, q.min);
  if (r.lod_psnr_aa.empty()) return;
  // Against the anti-aliased reference: this variant's frames, and full detail at the same poses.
  const Summary f = summarize(finite(r.lod_psnr_aa)), d = summarize(finite(r.full_psnr_aa));
  p["quality_vs_aa_reference"] = {{"compared", r.lod_psnr_aa.size()},
                                  {"psnr_db_mean_finite", f.mean},
                                  {"psnr_db_min", f.min},
                                  {"full_detail_psnr_db_mean_finite", d.mean},
                                  {"full_detail_psnr_db_min", d.min}};
  std::printf(
      "%-10s   vs the anti-aliased reference: %zu compared, PSNR mean %.2f dB, min %.2f dB (full detail: "
      "mean %.2f dB, min %.2f dB)\n",
      r.name.c_str(), r.lod_psnr_aa.size(), f.mean, f.min, d.mean, d.min);
}

// exact against vanilla, and every catgs variant against the full-frame pipelines of this run.
void ratios(const std::vector<PipelineResult>& results, nlohmann::json& j) {
  auto find = [&](const char* name) -> const PipelineResult* {
    for (const auto& r : results)
      if (r.name == name) return &r;
    return nullptr;
  };
  if (const auto* v = find("vanilla"), *e = find("exact"); v && e) {
    const double fps_ratio = mean(v->frame_ms) / mean(e->frame_ms);
    const double list_ratio = mean(v->list) / mean(e->list);
    std::printf("exact / vanilla: FPS x%.2f, render list %.2fx shorter\n", fps_ratio, list_ratio);
    j["exact_over_vanilla"] = {{"fps_ratio", fps_ratio}, {"render_list_ratio", list_ratio}};
  }
  for (const auto& r : results) {
    if (r.pipeline != Pipeline::catgs) continue;
    const double t = mean(r.frame_ms);
    for (const char* base : {"vanilla", "exact"}) {
      if (const auto* b = find(base)) {
        const double ratio = mean(b->frame_ms) / t;
        std::printf("%s / %s: FPS x%.2f\n", r.name.c_str(), base, ratio);
        j["fps_ratios"][r.name + "_over_" + base] = ratio;
      }
    }
  }
}

}  // namespace

nlohmann::json report(const BenchContext& context, const std::vector<PipelineResult>& results) {
  print_header(context);
  nlohmann::json j = context_json(context);
  for (const auto& r : results) {
    nlohmann::json p = table_row(r, context.scene_device_bytes);
    if (r.pipeline == Pipeline::catgs) {
      speculation_report(r, p);
      quality_report(r, p);
    }
    lod_quality_report(r, p);
    j["pipelines"].push_back(p);
  }
  ratios(results, j);
  return j;
}

void write_json(const nlohmann::json& json, const std::string& path) {
  std::ofstream out(path);
  out << json.dump(1) << "\n";
  if (!out) throw std::runtime_error(path + ": write failed");
}

}  // namespace catgs::bench
