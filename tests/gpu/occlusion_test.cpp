// occlusion: culling list entries behind the last frame's opaque pixels (forward_model/occlusion.h,
// issue 72), the CUDA core against the CPU reference, both with RenderOptions::occlusion_culling,
// frame after frame along a real camera path (bicycle) on the 13-copy tumblewood city with its
// level of detail at 2 px:
//  cpu           CUDA == CPU on every 8th frame (>= 45 dB; each core draws from its own map, and
//                alpha's rounding can move a tile's opaque point by a round of 256 entries, so
//                the lists may differ by a few chunks' entries) and the lists within 2%;
//  unculled      CUDA with culling against CUDA without, the same frames (>= 40 dB: the picture
//                the culling must keep), and fewer entries in all than without (it culls);
//  chunks        the chunks pre-processed, summed over the path: CUDA == CPU within 0.5% (the
//                chunks the map hides whole), and fewer than without culling;
//  still         the same pose twice: the second frame (culled) against the first (unculled map)
//                >= 48 dB (under one 8-bit level a pixel, with the sort's ties).
#include <cmath>
#include <cstdio>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

catgs::RenderOptions occlusion_options(bool on) {
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.lod_error_px = 2.0f;
  o.occlusion_culling = on;
  return o;
}

class Occlusion : public GpuTest {};

TEST_F(Occlusion, CudaAgainstCpuAlongARealPath) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  const CityWithLod& c = city13_with_lod();
  catgs::cpu::CpuRenderer cpu(c.lod, occlusion_options(true));
  catgs::cuda::CudaRenderer gpu(c.dev, occlusion_options(true)), plain(c.dev, occlusion_options(false));
  long long culled = 0, unculled = 0, chunks_cpu = 0, chunks_gpu = 0, chunks_plain = 0;
  double worst = INFINITY;
  for (std::size_t k = 0; k < c.trace.size(); ++k) {
    Image a, b, p;
    const Camera& cam = c.trace[k].camera;
    gpu.render(cam, b);
    plain.render(cam, p);
    culled += static_cast<long long>(gpu.last_stats().render_list_length);
    unculled += static_cast<long long>(plain.last_stats().render_list_length);
    worst = std::fmin(worst, compare(b, p).psnr);
    // The CPU draws every frame (its map must follow the path) and is compared every 8th.
    cpu.render(cam, a);
    chunks_cpu += static_cast<long long>(cpu.last_stats().chunks_preprocessed);
    chunks_gpu += static_cast<long long>(gpu.last_stats().chunks_preprocessed);
    chunks_plain += static_cast<long long>(plain.last_stats().chunks_preprocessed);
    if (k % 8 != 0) continue;
    const Diff d = compare(a, b);
    const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
    const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
    add({"occlusion", "tumblewood_sh2 x13 lod", "bicycle" + std::to_string(k), "exact-occlusion/cpu", d.psnr, d.max_abs,
         d.max_abs8, lc, lg, d.psnr >= 45.0 && std::llabs(lc - lg) <= lc / 50 + 16, ""});
  }
  add({"occlusion", "tumblewood_sh2 x13 lod", "bicycle all", "exact-occlusion/exact", worst, 0, 0, unculled, culled,
       worst >= 40.0 && culled < unculled, "worst frame; lists summed over the path"});
  // Chunks the map hides whole (fm::chunk_hidden) are not pre-processed: the cores agree on them
  // (each from its own map) and some go.
  add({"occlusion", "tumblewood_sh2 x13 lod", "bicycle all", "chunks cpu/cuda", 0, 0, 0, chunks_cpu, chunks_gpu,
       std::llabs(chunks_cpu - chunks_gpu) <= chunks_cpu / 200 + 4 && chunks_gpu < chunks_plain,
       "chunks pre-processed summed over the path; unculled " + std::to_string(chunks_plain)});
}

TEST_F(Occlusion, SamePoseTwice) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  const CityWithLod& c = city13_with_lod();
  for (std::size_t k = 0; k < c.trace.size(); k += c.trace.size() / 3) {
    catgs::cuda::CudaRenderer gpu(c.dev, occlusion_options(true));
    Image first, again;
    gpu.render(c.trace[k].camera, first);
    const auto l0 = static_cast<long long>(gpu.last_stats().render_list_length);
    gpu.render(c.trace[k].camera, again);
    const auto l1 = static_cast<long long>(gpu.last_stats().render_list_length);
    const Diff d = compare(first, again);
    add({"occlusion", "tumblewood_sh2 x13 lod", "bicycle" + std::to_string(k), "still", d.psnr, d.max_abs, d.max_abs8,
         l0, l1, d.psnr >= 48.0 && l1 <= l0 && gpu.last_stats().occlusion_map_used,
         "first frame vs the same pose culled"});
  }
}

}  // namespace
}  // namespace catgs::gputest
