// lod: level of detail (forward_model/lod.h): the cut both cores take, CUDA against the CPU, on 13
// tumblewood copies with their level of detail (lod/lod_build.h), along the fly-over at
// 120 FPS:
//  exact@1, exact@4  CUDA exact == CPU exact on the fly-over's views at the default
//                    RenderOptions::lod_error_px and at 4 px (where many merged chunks are drawn;
//                    >= 50 dB, the same list);
//  tau0              CUDA exact at lod_error_px 0 on the LOD scene == CUDA exact on the scene
//                    without LOD (bit for bit), and fewer chunks kept at 4 px than without LOD;
//  catgs@4           CUDA catgs vs CPU catgs at 4 px frame by frame (the same key/sub-frame
//                    decisions on >= 95% of frames, >= 50 dB where they agree, some sub-frames).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "gpu_test_support.h"
#include "lod/lod_build.h"
#include "scene/morton.h"

namespace catgs::gputest {
namespace {

constexpr float kCoarse = 4.0f;  // a bound that draws many merged chunks on this city

// The 13-copy city with its LOD, its fly-over, and the scene without LOD in the LOD's leaf order
// (Morton, for the bit-for-bit check at tau 0); built once per process.
struct LodCity {
  TestCity city;
  catgs::LodBuildReport built;
  std::shared_ptr<GaussianModel> lod, full;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev, dev_full;
  catgs::Trace trace;
  std::string levels;
};

const LodCity& lod_city() {
  static const LodCity c = [] {
    LodCity k;
    k.city = test_city(4);  // 13 cells
    k.lod = std::make_shared<GaussianModel>(catgs::build_lod(*k.city.model, {}, &k.built));
    k.full = std::make_shared<GaussianModel>(catgs::permuted(*k.city.model, catgs::morton_order(*k.city.model)));
    k.dev = catgs::cuda::DeviceScene::upload(*k.lod);
    k.dev_full = catgs::cuda::DeviceScene::upload(*k.full);
    catgs::GeneratorParams g;
    g.width = config().W;
    g.height = config().H;
    g.duration_s = 0.5;  // 61 frames: the CPU's catgs frames of 7 M Gaussians take the time
    g.rate_hz = 120.0;
    k.trace = catgs::make_city_flyover(k.city.layout, catgs::FlyoverParams{}, g);
    k.levels = std::to_string(k.lod->size()) + " Gaussians, " + std::to_string(k.built.level_nodes.size()) +
               " levels, built in " + std::to_string(k.built.seconds) + " s";
    return k;
  }();
  return c;
}

// CUDA exact == CPU exact on 5 views of the fly-over at LOD bound `bound`.
void exact_at(float bound) {
  const LodCity& c = lod_city();
  catgs::RenderOptions ob;
  ob.pipeline = Pipeline::exact;
  ob.lod_error_px = bound;
  catgs::cpu::CpuRenderer cpu(c.lod, ob);
  catgs::cuda::CudaRenderer gpu(c.dev, ob);
  for (std::size_t k = 0; k < c.trace.size(); k += c.trace.size() / 4) {
    Image a, b;
    cpu.render(c.trace[k].camera, a);
    gpu.render(c.trace[k].camera, b);
    const Diff d = compare(a, b);
    const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
    const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
    add({"lod", c.lod->name, "fly" + std::to_string(k), "exact@" + std::to_string(static_cast<int>(bound)), d.psnr,
         d.max_abs, d.max_abs8, lc, lg, d.psnr >= 50.0 && lc == lg, c.levels});
  }
}

class Lod : public GpuTest {};

TEST_F(Lod, ExactDefaultBound) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  exact_at(catgs::RenderOptions{}.lod_error_px);
}

TEST_F(Lod, ExactCoarseBound) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  exact_at(kCoarse);
}

TEST_F(Lod, TauZero) {  // tau 0: the leaves only, the scene as it was
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  const LodCity& c = lod_city();
  catgs::RenderOptions zero, coarse;
  zero.pipeline = coarse.pipeline = Pipeline::exact;
  zero.lod_error_px = 0.0f;
  coarse.lod_error_px = kCoarse;
  catgs::cuda::CudaRenderer a_gpu(c.dev, zero), b_gpu(c.dev_full, zero), tau_gpu(c.dev, coarse);
  Image a, b, t;
  const Camera& cam = c.trace[c.trace.size() / 2].camera;
  a_gpu.render(cam, a);
  b_gpu.render(cam, b);
  tau_gpu.render(cam, t);
  const Diff d = compare(a, b);
  const auto kept_lod = tau_gpu.diagnostics().chunks_kept, kept_full = b_gpu.diagnostics().chunks_kept;
  add({"lod", c.lod->name, "tau0", "exact", d.psnr, d.max_abs, d.max_abs8,
       static_cast<long long>(b_gpu.last_stats().render_list_length),
       static_cast<long long>(a_gpu.last_stats().render_list_length), d.max_abs == 0.0 && kept_lod < kept_full,
       "vs the scene without LOD; chunks kept at 4 px " + std::to_string(kept_lod) + ", without LOD " +
           std::to_string(kept_full)});
}

TEST_F(Lod, CatgsCoarseBound) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  const LodCity& c = lod_city();
  catgs::RenderOptions co;
  co.pipeline = Pipeline::catgs;
  co.lod_error_px = kCoarse;
  catgs::cpu::SpeculativeRenderer cpu(c.lod, co);
  catgs::cuda::CudaRenderer gpu(c.dev, co);
  std::size_t agree = 0, subs = 0;
  double min_psnr = INFINITY, max_abs = 0;
  int max8 = 0;
  for (const auto& f : c.trace) {
    Image a, b;
    cpu.render_at(f.camera, f.time_s, a);
    gpu.render_at(f.camera, f.time_s, b);
    if (cpu.last_stats().key_frame != gpu.last_stats().key_frame) continue;
    ++agree;
    subs += gpu.last_stats().key_frame ? 0 : 1;
    const Diff d = compare(a, b);
    min_psnr = std::min(min_psnr, d.psnr);
    max_abs = std::max(max_abs, d.max_abs);
    max8 = std::max(max8, d.max_abs8);
  }
  char note[160];
  std::snprintf(note, sizeof note, "%zu frames: decisions agree on %zu (%zu sub-frames)", c.trace.size(), agree, subs);
  add({"lod", c.lod->name, "flyover", "catgs@4", min_psnr, max_abs, max8, -1, -1,
       agree * 100 >= c.trace.size() * 95 && min_psnr >= 50.0 && subs > 0, note});
}

}  // namespace
}  // namespace catgs::gputest
