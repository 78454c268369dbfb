// passes: the render-list budget's passes and narrowed windows (renderer.h, issue 35), CUDA as the
// CPU core, biker at 1280x720:
//  vanilla, exact  a third of their list a pass: >= 3 passes, as many as the CPU's, each within
//                  the limit, the list's total the one-pass length, PSNR >= 50 dB vs the CPU's
//                  passes and >= 60 dB vs one CUDA pass;
//  catgs           over a 40 deg/s orbit: (orbit-fb) a budget of a third of the exact list: every
//                  frame an exact frame in passes, >= 60 dB vs the unbudgeted CUDA exact frame;
//                  (orbit-nw) a budget halfway between the windowed key lists: some key frames
//                  narrowed; both: CPU and CUDA take the same decisions (key frame, W, narrowed,
//                  passes) on >= 95% of frames and agree >= 50 dB there.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <string>

#include "gpu_test_support.h"
#include "scene/scene_bounds.h"

namespace catgs::gputest {
namespace {

// vanilla, exact: a third of the list a pass; the image equals one pass (the same entries per
// tile, sorted with the frame's key, split with its slice length) and the CPU's passes.
void passes_check(Pipeline p) {
  const auto& model = biker().model;
  const auto& dev = biker().dev;
  const Camera cam = orbit_views(*model, config().W, config().H)[1];
  catgs::RenderOptions o;
  o.pipeline = p;
  o.speculation.min_slice_entries = 0;  // the paper's slice length: tiles really split
  catgs::cuda::CudaRenderer one(dev, o);
  Image g1, g, c;
  one.render(cam, g1);
  const std::uint64_t entries = one.last_stats().render_list_length, limit = entries / 3;
  o.list_budget = pass_budget(limit);
  catgs::cpu::CpuRenderer cpu(model, o);
  catgs::cuda::CudaRenderer gpu(dev, o);
  cpu.render(cam, c);
  gpu.render(cam, g);
  const catgs::FrameStats &cs = cpu.last_stats(), &gs = gpu.last_stats();
  const Diff vs_cpu = compare(c, g), vs_one = compare(g, g1);
  char note[200];
  std::snprintf(note, sizeof note,
                "%d passes (CPU %d), longest %zu of %llu a pass; vs one CUDA pass: %s dB, max abs %.3g", gs.passes,
                cs.passes, gs.longest_pass, static_cast<unsigned long long>(limit), fmt_psnr(vs_one.psnr).c_str(),
                vs_one.max_abs);
  add({"passes", model->name, "orbit1", catgs::pipeline_name(p), vs_cpu.psnr, vs_cpu.max_abs, vs_cpu.max_abs8,
       static_cast<long long>(cs.render_list_length), static_cast<long long>(gs.render_list_length),
       vs_cpu.psnr >= 50.0 && vs_one.psnr >= 60.0 && gs.passes >= 3 && gs.passes == cs.passes &&
           gs.longest_pass <= limit && gs.render_list_length == entries,
       note});
}

// catgs over an orbit (40 degrees a second, 0.3 s at 120 Hz). fallback: a third of the exact
// list, so every key frame falls back to an exact frame in passes (compared with the unbudgeted
// CUDA exact frame of its pose); narrowed: halfway between the windowed key lists, so the longer
// ones narrow (CPU and CUDA must narrow alike).
void catgs_passes_check(bool fallback) {
  const auto& model = biker().model;
  const auto& dev = biker().dev;
  catgs::GeneratorParams gp;
  gp.width = config().W;
  gp.height = config().H;
  gp.duration_s = 0.3;
  gp.up = {0.0f, -1.0f, 0.0f};
  const auto rb = catgs::robust_bounds(*model);
  const glm::vec3 e = rb.extent();
  const float r = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const catgs::Trace trace = catgs::make_orbit(rb, r, 0.3f * r, 12.0f, gp);
  catgs::RenderOptions o = catgs_options();
  o.speculation.min_slice_entries = 0;
  catgs::RenderOptions exact_o = o;
  exact_o.pipeline = Pipeline::exact;
  catgs::cuda::CudaRenderer exact(dev, exact_o);
  Image x;
  exact.render(trace[0].camera, x);
  const std::uint64_t exact_entries = exact.last_stats().render_list_length;
  // The unbudgeted CPU run's key-frame lists with a window: the budget goes halfway between.
  std::uint64_t shortest = UINT64_MAX, longest = 0;
  {
    catgs::cpu::SpeculativeRenderer free_run(model, o);
    Image a;
    for (const auto& tc : trace) {
      free_run.render_at(tc.camera, tc.time_s, a);
      const catgs::FrameStats& st = free_run.last_stats();
      if (st.key_frame && st.window > 0) {
        shortest = std::min<std::uint64_t>(shortest, st.render_list_length);
        longest = std::max<std::uint64_t>(longest, st.render_list_length);
      }
    }
  }
  const std::uint64_t limit = fallback ? exact_entries / 3 : shortest + (longest - shortest) / 2;
  catgs::RenderOptions bo = o;
  bo.list_budget = pass_budget(limit);
  catgs::cpu::SpeculativeRenderer cpu(model, bo);
  catgs::cuda::CudaRenderer gpu(dev, bo);
  Image c, g;
  int agree = 0, narrowed = 0, in_passes = 0;
  double min_psnr = 1e9, min_vs_exact = 1e9, max_abs = 0;
  int max_abs8 = 0;
  for (const auto& tc : trace) {
    cpu.render_at(tc.camera, tc.time_s, c);
    gpu.render_at(tc.camera, tc.time_s, g);
    const catgs::FrameStats &cs = cpu.last_stats(), &gs = gpu.last_stats();
    const bool same = cs.key_frame == gs.key_frame && cs.window == gs.window &&
                      cs.window_narrowed == gs.window_narrowed && cs.passes == gs.passes;
    agree += same ? 1 : 0;
    narrowed += gs.window_narrowed ? 1 : 0;
    in_passes += gs.passes > 1 ? 1 : 0;
    if (same) {
      const Diff d = compare(c, g);
      min_psnr = std::min(min_psnr, d.psnr);
      max_abs = std::max(max_abs, d.max_abs);
      max_abs8 = std::max(max_abs8, d.max_abs8);
    }
    if (fallback) {
      exact.render(tc.camera, x);
      min_vs_exact = std::min(min_vs_exact, compare(g, x).psnr);
    }
  }
  const int frames = static_cast<int>(trace.size());
  char note[200];
  std::snprintf(note, sizeof note, "limit %llu: %d/%d frames agree, %d narrowed, %d in passes%s%s",
                static_cast<unsigned long long>(limit), agree, frames, narrowed, in_passes,
                fallback ? "; vs unbudgeted CUDA exact min " : "",
                fallback ? (fmt_psnr(min_vs_exact) + " dB").c_str() : "");
  const bool pass = 100 * agree >= 95 * frames && min_psnr >= 50.0 &&
                    (fallback ? in_passes == frames && min_vs_exact >= 60.0 : narrowed > 0 && shortest < longest);
  add({"passes", model->name, fallback ? "orbit-fb" : "orbit-nw", "catgs", min_psnr, max_abs, max_abs8,
       static_cast<long long>(cpu.last_stats().render_list_length),
       static_cast<long long>(gpu.last_stats().render_list_length), pass, note});
}

class Passes : public GpuTest {};

TEST_F(Passes, Vanilla) {
  CATGS_GPU_REQUIRE({"biker"});
  passes_check(Pipeline::vanilla);
}

TEST_F(Passes, Exact) {
  CATGS_GPU_REQUIRE({"biker"});
  passes_check(Pipeline::exact);
}

TEST_F(Passes, CatgsFallback) {
  CATGS_GPU_REQUIRE({"biker"});
  catgs_passes_check(true);
}

TEST_F(Passes, CatgsNarrowed) {
  CATGS_GPU_REQUIRE({"biker"});
  catgs_passes_check(false);
}

}  // namespace
}  // namespace catgs::gputest
