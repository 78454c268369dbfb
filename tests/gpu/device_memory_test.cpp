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

#include "forward_model/chunk_bounds.h"
#include "gpu_test_support.h"
#include "lod/lod_build.h"
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
        Row row{"device_memory",
                s->model->name,
                std::to_string(w) + "x" + std::to_string(h),
                pipeline_name(pipeline),
                0,
                0,
                0,
                -1,
                -1,
                false,
                ""};
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
          SessionBufferShape used = shape;  // the slots a small scene's renderer starts with: all
          used.gaussians = fm::initial_slot_chunks(fm::chunk_count(s->model->size())) * fm::kChunkSize;
          used.list_entries = longest;
          const std::uint64_t floor = session_device_bytes(used) / 2;
          row.list_gpu = static_cast<long long>(longest);
          // The scene copy's bytes as the CPU-side accounting gives them, against what the upload
          // allocated (DeviceScene::bytes).
          const std::uint64_t scene_bytes = scene_device_bytes(*s->model);
          row.pass = most <= estimate && most >= floor && scene_bytes == s->dev->bytes();
          row.note = "buffers " + std::to_string(most >> 20) + " MiB, estimate " + std::to_string(estimate >> 20) +
                     " MiB, floor " + std::to_string(floor >> 20) + " MiB; scene " + std::to_string(scene_bytes) +
                     " bytes, uploaded " + std::to_string(s->dev->bytes());
        } catch (const std::exception& e) {
          row.note = e.what();
        }
        add(row);
      }
    }
  }
}

// Issue 61: the buffers follow the view, not the scene. On the 13-copy city with its LOD at the
// default bound, along the fly-over: every frame equals the CPU reference's (>= 50 dB, the same
// list), including the first, whose view kept more chunks than the renderer's first slots held
// (pre-processed again once they grew); and after each frame the renderer's buffers are within
// what the accounting gives for the most chunks a view has kept so far (its slots, with their
// growth slack) and the longest list, and under what the same lists with per-Gaussian buffers
// over the whole scene take (the layout before issue 61).
TEST_F(DeviceMemory, BuffersFollowTheViewOnTheCity) {
  const TestCity city = test_city(4);
  const auto lod = std::make_shared<GaussianModel>(build_lod(*city.model, {}));
  const auto dev = cuda::DeviceScene::upload(*lod);
  GeneratorParams g;
  g.width = 1280;
  g.height = 720;
  g.duration_s = 0.5;
  g.rate_hz = 120.0;
  const Trace trace = make_city_flyover(city.layout, FlyoverParams{}, g);
  RenderOptions o;
  cpu::CpuRenderer reference(lod, o);
  cuda::CudaRenderer r(dev, o);
  std::uint64_t most_kept = 0, longest = 0;
  for (std::size_t k = 0; k < trace.size(); k += trace.size() / 4) {
    Image a, b;
    reference.render(trace[k].camera, a);
    r.render(trace[k].camera, b);
    const Diff d = compare(a, b);
    const auto lc = static_cast<long long>(reference.last_stats().render_list_length);
    const auto lg = static_cast<long long>(r.last_stats().render_list_length);
    const std::uint64_t bytes = r.device_buffer_bytes();
    most_kept = std::max<std::uint64_t>(most_kept, r.diagnostics().chunks_kept);
    longest = std::max<std::uint64_t>(longest, r.last_stats().render_list_length);
    SessionBufferShape view;
    view.gaussians = static_cast<std::uint64_t>(static_cast<double>(most_kept * fm::kChunkSize) * BufferBytes::kGrowth);
    view.width = g.width;
    view.height = g.height;
    view.list_entries = longest;
    SessionBufferShape scene = view;
    scene.gaussians = lod->size();
    const std::uint64_t by_view = session_device_bytes(view), by_scene = session_device_bytes(scene);
    add({"device_memory", lod->name, "fly" + std::to_string(k), "exact", d.psnr, d.max_abs, d.max_abs8, lc, lg,
         d.psnr >= 50.0 && lc == lg && bytes <= by_view && by_view < by_scene,
         "buffers " + std::to_string(bytes >> 20) + " MiB; the accounting by the view " +
             std::to_string(by_view >> 20) + " MiB, by the scene " + std::to_string(by_scene >> 20) +
             " MiB; chunks kept " + std::to_string(r.diagnostics().chunks_kept) + " of " +
             std::to_string(r.diagnostics().chunks)});
  }
}

}  // namespace
}  // namespace catgs::gputest
