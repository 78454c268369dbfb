// tiles18 (label gpu_large): 8192x4608 (147456 tiles, 18 tile-key bits), CUDA == CPU on biker
// (>= 50 dB), vanilla and exact.
#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

void tile_bits_check(Pipeline p) {
  const Camera cam = orbit_views(*biker().model, 8192, 4608)[0];
  catgs::RenderOptions o;
  o.pipeline = p;
  catgs::cpu::CpuRenderer c(biker().model, o);
  catgs::cuda::CudaRenderer g(biker().dev, o);
  Image a, b;
  c.render(cam, a);
  g.render(cam, b);
  const Diff d = compare(a, b);
  add({"tiles18", "sc.biker", "8192x4608", catgs::pipeline_name(p), d.psnr, d.max_abs, d.max_abs8,
       static_cast<long long>(c.last_stats().render_list_length),
       static_cast<long long>(g.last_stats().render_list_length), d.psnr >= 50.0, "147456 tiles, 18 tile bits"});
}

class TileBits : public GpuTest {};

TEST_F(TileBits, Vanilla) {
  CATGS_GPU_REQUIRE({"biker"});
  tile_bits_check(Pipeline::vanilla);
}

TEST_F(TileBits, Exact) {
  CATGS_GPU_REQUIRE({"biker"});
  tile_bits_check(Pipeline::exact);
}

}  // namespace
}  // namespace catgs::gputest
