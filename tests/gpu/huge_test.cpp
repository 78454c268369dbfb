// huge: more huge Gaussians than key emission keeps part counts for (tunables.h kHugeListed): the
// first kHugeListed are counted and emitted a block per part, the rest a block each. Every
// Gaussian of the wall covers the whole image, so each is huge; the list and image must be the
// CPU reference's (>= 50 dB, the same list).
#include <string>

#include "cuda/tunables.h"
#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

class Huge : public GpuTest {};

TEST_F(Huge, MoreThanHugeListed) {
  const Camera cam = front_camera(640, 360);
  auto wall = wall_scene(static_cast<std::size_t>(catgs::cuda::tune::kHugeListed) + 2000);
  catgs::RenderOptions o;
  o.pipeline = Pipeline::exact;
  o.list_budget.max_entries_per_tile = 1u << 20;  // 18 k entries a tile
  catgs::cpu::CpuRenderer cpu(wall, o);
  catgs::cuda::CudaRenderer gpu(catgs::cuda::DeviceScene::upload(*wall), o);
  Image c, g;
  cpu.render(cam, c);
  gpu.render(cam, g);
  const Diff d = compare(c, g);
  const auto lc = static_cast<long long>(cpu.last_stats().render_list_length);
  const auto lg = static_cast<long long>(gpu.last_stats().render_list_length);
  add({"huge", wall->name, "front", "exact", d.psnr, d.max_abs, d.max_abs8, lc, lg, d.psnr >= 50.0 && lc == lg,
       std::to_string(wall->size()) + " Gaussians of 920 tiles each"});
}

}  // namespace
}  // namespace catgs::gputest
