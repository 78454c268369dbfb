// steady: 1000 frames in a row (after a warm pass over the same trace), vanilla and exact in turn,
// on tumblewood_sh2 x10: no buffer growth, no allocation, no change in device memory in use, and
// one host sync a frame. Not under compute-sanitizer, whose own allocations move the device's
// memory in use (it is not in the quick subset).
#include <algorithm>
#include <string>

#include "gpu_test_support.h"
#include "scene/scene_bounds.h"

namespace catgs::gputest {
namespace {

class Steady : public GpuTest {};

TEST_F(Steady, DeviceMemory1000Frames) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"});
  const int W = config().W, H = config().H;
  auto& m = tumblewood().model;
  auto& dev = tumblewood().dev;
  catgs::GeneratorParams g;
  g.width = W;
  g.height = H;
  g.rate_hz = 120.0;
  g.duration_s = 999.0 / 120.0;
  const auto rb = catgs::robust_bounds(*m);
  const glm::vec3 e = rb.extent();
  const float rad = 0.6f * std::max(e.x, std::max(e.y, e.z));
  const auto trace = catgs::make_orbit(rb, rad, 0.3f * rad, 360.0f, g);
  catgs::RenderOptions o;
  catgs::cuda::CudaRenderer r(dev, o);
  auto pass = [&] {
    for (std::size_t i = 0; i < trace.size(); ++i) {
      o.pipeline = i % 2 ? Pipeline::vanilla : Pipeline::exact;
      r.set_options(o);
      r.render_device(trace[i].camera);
    }
    (void)r.last_stats();
  };
  pass();  // warm: buffers reach the trace's needs
  const std::size_t used0 = catgs::cuda::device_memory_used(), buf0 = r.diagnostics().buffer_bytes,
                    alloc0 = r.diagnostics().allocations;
  pass();
  const std::size_t used1 = catgs::cuda::device_memory_used(), buf1 = r.diagnostics().buffer_bytes,
                    alloc1 = r.diagnostics().allocations;
  Row row{"steady", m->name, "1000f", "both", 0, 0, 0, -1, -1, false, ""};
  row.pass = used0 == used1 && buf0 == buf1 && alloc0 == alloc1 && r.diagnostics().syncs_last_frame == 1;
  row.note = "device used " + std::to_string(used0 >> 20) + " -> " + std::to_string(used1 >> 20) + " MiB, buffers " +
             std::to_string(buf0) + " -> " + std::to_string(buf1) + " B, allocations " + std::to_string(alloc0) +
             " -> " + std::to_string(alloc1) + ", syncs/frame " + std::to_string(r.diagnostics().syncs_last_frame);
  add(row);
}

}  // namespace
}  // namespace catgs::gputest
