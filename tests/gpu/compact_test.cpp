// compact: the compact layout on the GPU (issue 74; cuda_renderer.h DeviceScene::compact, the
// codes decoded where a Gaussian is read: cuda/scene_fields.cuh), on 13 tumblewood copies with
// their level of detail quantized as the compact scene keeps them (quantize_compact), along the
// fly-over at 120 FPS:
//  bytes           the compact layout holds at most 48 bytes a Gaussian (the float layout 98);
//  layouts@P       CUDA in the compact layout == CUDA in the float layout of the same quantized
//                  model, bit for bit (the device decode gives the host decode's floats), at the
//                  default bound and at 4 px, exact and vanilla on 5 views;
//  cpu@P           CUDA compact == CPU on the quantized model (>= 50 dB, the same list);
//  catgs           CUDA catgs compact == CUDA catgs float, frame by frame, bit for bit (the same
//                  key/sub-frame decisions).
#include <cstdio>
#include <string>

#include "gpu_test_support.h"
#include "lod/lod_build.h"
#include "scene/compact_file.h"

namespace catgs::gputest {
namespace {

struct CompactCity {
  TestCity city;
  std::shared_ptr<GaussianModel> quantized, plain;  // plain: the same floats without codes
  std::shared_ptr<const catgs::cuda::DeviceScene> compact, floats;
  catgs::Trace trace;
};

const CompactCity& compact_city() {
  static const CompactCity c = [] {
    CompactCity k;
    k.city = test_city(4);  // 13 cells
    k.quantized = std::make_shared<GaussianModel>(catgs::build_lod(*k.city.model));
    catgs::quantize_compact(*k.quantized);
    k.plain = std::make_shared<GaussianModel>(*k.quantized);
    k.plain->codes.reset();
    k.compact = catgs::cuda::DeviceScene::upload(*k.quantized);
    k.floats = catgs::cuda::DeviceScene::upload(*k.plain);
    catgs::GeneratorParams g;
    g.width = config().W;
    g.height = config().H;
    g.duration_s = 0.5;
    g.rate_hz = 120.0;
    k.trace = catgs::make_city_flyover(k.city.layout, catgs::FlyoverParams{}, g);
    return k;
  }();
  return c;
}

class Compact : public GpuTest {};

TEST_F(Compact, Bytes) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  const CompactCity& c = compact_city();
  const double per = double(c.compact->bytes()) / double(c.quantized->size());
  const double before = double(c.floats->bytes()) / double(c.plain->size());
  char note[160];
  std::snprintf(note, sizeof note, "%.1f bytes a Gaussian on the GPU, the float layout %.1f", per, before);
  add({"compact", c.quantized->name, "-", "bytes", 0, 0, 0, -1, -1,
       c.compact->compact() && !c.floats->compact() && per <= 48.0, note});
}

void layouts_at(float bound, Pipeline p) {
  const CompactCity& c = compact_city();
  catgs::RenderOptions o;
  o.pipeline = p;
  o.lod_error_px = bound;
  catgs::cuda::CudaRenderer a(c.compact, o), b(c.floats, o);
  catgs::cpu::CpuRenderer cpu(c.plain, o);
  for (std::size_t k = 0; k < c.trace.size(); k += c.trace.size() / 4) {
    Image ia, ib, ic;
    a.render(c.trace[k].camera, ia);
    b.render(c.trace[k].camera, ib);
    const Diff same = compare(ia, ib);
    char bound_text[16];
    std::snprintf(bound_text, sizeof bound_text, "@%g", bound);
    const std::string at = catgs::pipeline_name(p) + std::string(bound_text);
    add({"compact", c.quantized->name, "fly" + std::to_string(k), "layouts " + at, same.psnr, same.max_abs,
         same.max_abs8, static_cast<long long>(b.last_stats().render_list_length),
         static_cast<long long>(a.last_stats().render_list_length), same.max_abs == 0.0 && ia.rgba8 == ib.rgba8,
         "compact vs float layout, bit for bit"});
    if (p != Pipeline::exact) continue;
    cpu.render(c.trace[k].camera, ic);
    const Diff d = compare(ic, ia);
    const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
    const auto lg = static_cast<long long>(a.last_stats().render_list_length);
    add({"compact", c.quantized->name, "fly" + std::to_string(k), "cpu " + at, d.psnr, d.max_abs, d.max_abs8, lc, lg,
         d.psnr >= 50.0 && lc == lg, "CUDA compact vs the CPU reference"});
  }
}

TEST_F(Compact, ExactDefaultBound) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  layouts_at(catgs::RenderOptions{}.lod_error_px, Pipeline::exact);
}

TEST_F(Compact, ExactCoarseBound) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  layouts_at(4.0f, Pipeline::exact);
}

TEST_F(Compact, Vanilla) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  layouts_at(catgs::RenderOptions{}.lod_error_px, Pipeline::vanilla);
}

TEST_F(Compact, Catgs) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  const CompactCity& c = compact_city();
  catgs::RenderOptions o;
  o.pipeline = Pipeline::catgs;
  catgs::cuda::CudaRenderer a(c.compact, o), b(c.floats, o);
  std::size_t same_frames = 0, subs = 0;
  double max_abs = 0;
  for (const auto& f : c.trace) {
    Image ia, ib;
    a.render_at(f.camera, f.time_s, ia);
    b.render_at(f.camera, f.time_s, ib);
    const bool same = a.last_stats().key_frame == b.last_stats().key_frame && ia.rgba8 == ib.rgba8 && ia.rgb == ib.rgb;
    same_frames += same ? 1 : 0;
    subs += a.last_stats().key_frame ? 0 : 1;
    max_abs = std::max(max_abs, compare(ia, ib).max_abs);
  }
  char note[160];
  std::snprintf(note, sizeof note, "%zu frames, %zu the same bit for bit (%zu sub-frames)", c.trace.size(), same_frames,
                subs);
  add({"compact", c.quantized->name, "flyover", "catgs layouts", 0, max_abs, 0, -1, -1,
       same_frames == c.trace.size() && subs > 0, note});
}

}  // namespace
}  // namespace catgs::gputest
