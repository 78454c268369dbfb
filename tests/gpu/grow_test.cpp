// grow: one renderer across scenes and sizes (small -> large -> small): every frame equals a fresh
// renderer's frame (bit for bit, the same list), and buffers grow without errors.
#include <exception>
#include <string>

#include "gpu_test_support.h"

namespace catgs::gputest {
namespace {

class Grow : public GpuTest {};

TEST_F(Grow, AcrossScenesAndSizes) {
  CATGS_GPU_REQUIRE({"biker", "tumblewood_sh2", "flowers_sh3"});
  const SharedScene &bk = biker(), &tw = tumblewood(), &fl = flowers();
  catgs::RenderOptions o;
  catgs::cuda::CudaRenderer r(bk.dev, o);
  struct Step {
    std::shared_ptr<const catgs::cuda::DeviceScene> dev;
    std::shared_ptr<GaussianModel> m;
    int w, h;
  };
  const Step steps[] = {{bk.dev, bk.model, 640, 360},
                        {tw.dev, tw.model, 1920, 1080},
                        {fl.dev, fl.model, 1280, 720},
                        {bk.dev, bk.model, 640, 360},
                        {tw.dev, tw.model, 1920, 1080}};
  int k = 0;
  for (const Step& s : steps) {
    Row row{"grow", s.m->name, std::to_string(k++), "exact", 0, 0, 0, -1, -1, false, ""};
    try {
      r.set_scene(s.dev);
      const Camera cam = orbit_views(*s.m, s.w, s.h)[1];
      Image a, b;
      r.render(cam, a);
      catgs::cuda::CudaRenderer fresh(s.dev, o);
      fresh.render(cam, b);
      const Diff d = compare(a, b);
      row.psnr = d.psnr;
      row.max_abs = d.max_abs;
      row.max_abs8 = d.max_abs8;
      row.list_gpu = static_cast<long long>(r.last_stats().render_list_length);
      row.list_ref = static_cast<long long>(fresh.last_stats().render_list_length);
      row.pass = d.max_abs == 0.0 && row.list_gpu == row.list_ref;
      row.note = std::to_string(s.w) + "x" + std::to_string(s.h) + ", buffers " +
                 std::to_string(r.diagnostics().buffer_bytes >> 20) + " MiB, allocations " +
                 std::to_string(r.diagnostics().allocations);
    } catch (const std::exception& e) {
      row.note = e.what();
    }
    add(row);
  }
}

}  // namespace
}  // namespace catgs::gputest
