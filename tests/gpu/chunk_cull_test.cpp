// chunkcull: chunk culling's kept-chunk list (preprocess.cu cull_chunks_kernel) against the CPU,
// after a frame that listed chunks this one culls (their tile counts are stale: records.h
// listed_tiles). 13 tumblewood copies: one CUDA exact renderer (single sort, and one depth first)
// draws a fly-over view, then a view of the centre copies, where most chunks are culled: CUDA ==
// CPU (>= 50 dB, the same list) on both, and fewer than half the chunks were kept on the second.
#include <memory>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

// The city and its upload, built once per process.
struct City13 {
  TestCity tc;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev;
};
const City13& city13() {
  static const City13 c = [] {
    City13 k;
    k.tc = test_city(4);  // 13 cells
    k.dev = catgs::cuda::DeviceScene::upload(*k.tc.model);
    return k;
  }();
  return c;
}

void chunk_cull_check(bool depth_first) {
  const TestCity& tc = city13().tc;
  const auto& city = tc.model;
  catgs::FlyoverParams centre;  // catgs-bench --trace centre
  centre.altitude = 0.4f;
  centre.pitch_deg = 70.0f;
  centre.start_cells = -0.25f;
  centre.end_cells = 0.25f;
  const Camera wide = tc.view(catgs::FlyoverParams{}), narrow = tc.view(centre);
  const auto& dev = city13().dev;
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  catgs::cpu::CpuRenderer cpu(city, o);
  catgs::cuda::CudaOptions co;
  co.depth_first_sort = depth_first;
  catgs::cuda::CudaRenderer gpu(dev, o, co);
  const char* views[2] = {"fly1", "centre1"};
  for (int v = 0; v < 2; ++v) {
    const Camera& cam = v == 0 ? wide : narrow;
    Image a, b;
    cpu.render(cam, a);
    gpu.render(cam, b);
    const Diff d = compare(a, b);
    const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
    const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
    const auto diag = gpu.diagnostics();
    const bool culled = v == 0 || 2 * diag.chunks_kept < diag.chunks;
    add({"chunkcull", city->name, views[v], depth_first ? "ex/depth" : "exact", d.psnr, d.max_abs, d.max_abs8, lc, lg,
         d.psnr >= 50.0 && lc == lg && culled,
         std::to_string(diag.chunks_kept) + " of " + std::to_string(diag.chunks) + " chunks kept"});
  }
}

class ChunkCull : public GpuTest {};

TEST_F(ChunkCull, SingleSort) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  chunk_cull_check(false);
}

TEST_F(ChunkCull, DepthFirstSort) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  chunk_cull_check(true);
}

}  // namespace
}  // namespace catgs::gputest
