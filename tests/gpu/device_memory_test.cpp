// device_memory: the server's accounting (renderer/device_memory.h, issue 61) against a real
// CudaRenderer. A session is admitted by session_device_bytes(); its buffers must never outgrow
// it, or a GPU the accounting calls full-but-fitting runs out mid-tour. Each row renders the
// three real scenes' orbit views through render_yuv420_at (the server's path, I420 planes to a
// host target) at the server's list budget, and checks the buffers after every frame against
// the estimate (an upper bound) and against the estimate with the frame's own list length (a
// lower bound of half of it: the estimate counts the buffers, not a guess).
#include <algorithm>
#include <exception>
#include <string>
#include <vector>

#include "gpu_test_support.h"
#include "renderer/device_memory.h"

namespace catgs::gputest {
namespace {

class DeviceMemory : public GpuTest {};

TEST_F(DeviceMemory, EstimateBoundsTheBuffers) {
  CATGS_GPU_REQUIRE({"biker", "tumblewood_sh2", "flowers_sh3"});
  const SharedScene* scenes[] = {&biker(), &tumblewood(), &flowers()};
  const std::pair<int, int> sizes[] = {{1280, 720}, {1920, 1080}};
  for (const Pipeline pipeline : {Pipeline::exact, Pipeline::catgs}) {
    for (const SharedScene* s : scenes) {
      for (const auto& [w, h] : sizes) {
        Row row{"device_memory", s->model->name, std::to_string(w) + "x" + std::to_string(h), pipeline_name(pipeline),
                0, 0, 0, -1, -1, false, ""};
        try {
          RenderOptions o = pipeline == Pipeline::catgs ? catgs_options() : RenderOptions{};
          o.list_budget.max_bytes = 512ull << 20;  // the server's --list-memory-mb default
          cuda::CudaRenderer r(s->dev, o);
          SessionBufferShape shape;
          shape.gaussians = s->model->size();
          shape.width = w;
          shape.height = h;
          shape.pipeline = pipeline;
          shape.list_entries = session_list_entries(o.list_budget, w, h);
          const std::uint64_t estimate = session_device_bytes(shape);
          std::vector<std::uint8_t> y(static_cast<std::size_t>(w) * h), u(y.size() / 4), v(y.size() / 4);
          const Yuv420Target target{w, h, MemoryKind::host, y.data(), w, u.data(), w / 2, v.data(), w / 2};
          std::uint64_t most = 0, longest = 0;
          double t = 0;
          for (const Camera& cam : orbit_views(*s->model, w, h)) {
            r.render_yuv420_at(cam, t += 1.0 / 60, target);
            most = std::max<std::uint64_t>(most, r.device_buffer_bytes());
            longest = std::max<std::uint64_t>(longest, r.last_stats().render_list_length);
          }
          SessionBufferShape used = shape;
          used.list_entries = longest;
          const std::uint64_t floor = session_device_bytes(used) / 2;
          row.list_gpu = static_cast<long long>(longest);
          row.pass = most <= estimate && most >= floor;
          row.note = "buffers " + std::to_string(most >> 20) + " MiB, estimate " + std::to_string(estimate >> 20) +
                     " MiB, floor " + std::to_string(floor >> 20) + " MiB";
        } catch (const std::exception& e) {
          row.note = e.what();
        }
        add(row);
      }
    }
  }
}

}  // namespace
}  // namespace catgs::gputest
