// allocation faults: an allocation that fails leaves the CUDA renderer whole (issue 73;
// base/allocation_faults.h; the CPU core's twin: tests/unit/allocation_faults_test.cpp). On the
// 13-copy tumblewood city with its LOD at 2 px, along the bicycle path's first frames and then a
// viewport change (twice the size, then half), the server's way (render_yuv420_at into host
// planes). For every N, a renderer whose Nth buffer growth fails draws the path; the frame that
// failed is drawn again (the server's next pose), and every frame is compared with the frame of a
// renderer that never failed (the oracle, the same options):
//  exact         the planes equal, frame for frame;
//  occlusion     >= 50 dB (a failed frame drops the map: the next draws unculled);
//  catgs         >= 35 dB (the group closes: its next frame is a key frame);
//  reserved      a renderer whose buffers were reserved at the oracle's shape (Renderer::
//                reserve_buffers, as a server session at the door) draws the path's first frames
//                with no allocation at all.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <vector>

#include "base/allocation_faults.h"
#include "colour/yuv420.h"
#include "gpu_test_support.h"
#include "lod/lod_build.h"

namespace catgs::gputest {
namespace {

struct FaultCity {
  std::shared_ptr<GaussianModel> lod;
  std::shared_ptr<const catgs::cuda::DeviceScene> dev;
  std::vector<Camera> path;
};

const FaultCity& fault_city() {
  static const FaultCity c = [] {
    FaultCity k;
    const TestCity city = test_city(4);  // 13 cells
    k.lod = std::make_shared<GaussianModel>(catgs::build_lod(*city.model));
    k.dev = catgs::cuda::DeviceScene::upload(*k.lod);
    const int w = config().W / 2, h = config().H / 2;
    const catgs::Trace trace = real_trace(*k.lod, trace_path("mipnerf360_bicycle"), w, h, 48);
    for (std::size_t f = 0; f < trace.size() && k.path.size() < 8; f += 6) {
      const Camera& c0 = trace[f].camera;
      const std::size_t n = k.path.size();
      const int scale_w = n >= 5 && n < 7 ? 2 * w : w, scale_h = n >= 5 && n < 7 ? 2 * h : h;
      k.path.push_back(Camera::from_pose(c0.position(), c0.orientation(), c0.vertical_fov_deg(), scale_w, scale_h));
    }
    return k;
  }();
  return c;
}

catgs::RenderOptions fault_options(Pipeline p, bool occlusion) {
  catgs::RenderOptions o = p == Pipeline::catgs ? catgs_options() : catgs::RenderOptions{};
  o.pipeline = p;
  o.lod_error_px = 2.0f;
  o.occlusion_culling = occlusion;
  return o;
}

// Counts the allocations the hook is asked about; fails the fail_at-th (1-based; 0: none).
struct Counter {
  std::atomic<int> seen{0};
  int fail_at = 0;
};
struct HookScope {
  explicit HookScope(Counter& c) {
    c.seen = 0;
    catgs::set_allocation_fault([&c](std::uint64_t, const char*) { return ++c.seen == c.fail_at; });
  }
  ~HookScope() { catgs::set_allocation_fault({}); }
};

// PSNR over the three planes (8-bit), inf when equal.
double planes_psnr(const catgs::Yuv420Image& a, const catgs::Yuv420Image& b) {
  if (a.width != b.width || a.height != b.height) return -1.0;
  double se = 0;
  std::size_t n = 0;
  for (const auto* pair : {&a.y, &a.u, &a.v}) {
    const auto& pa = *pair;
    const auto& pb = pair == &a.y ? b.y : pair == &a.u ? b.u : b.v;
    for (std::size_t k = 0; k < pa.size(); ++k) {
      const double d = static_cast<double>(pa[k]) - pb[k];
      se += d * d;
    }
    n += pa.size();
  }
  return se == 0 ? INFINITY : 10.0 * std::log10(255.0 * 255.0 / (se / static_cast<double>(n)));
}

void draw(catgs::cuda::CudaRenderer& r, const Camera& cam, catgs::Yuv420Image& out) {
  r.render_yuv420_at(cam, 0.0, out.target(cam.width, cam.height));
}

class AllocationFaults : public GpuTest {
 protected:
  void every_failure(const std::string& name, Pipeline p, bool occlusion, double min_psnr) {
    const FaultCity& c = fault_city();
    const catgs::RenderOptions o = fault_options(p, occlusion);
    std::vector<catgs::Yuv420Image> oracle(c.path.size());
    Counter counter;
    int allocations = 0;
    {
      catgs::cuda::CudaRenderer r(c.dev, o);
      const HookScope scope(counter);
      for (std::size_t k = 0; k < c.path.size(); ++k) draw(r, c.path[k], oracle[k]);
      allocations = counter.seen;
    }
    int wrong = 0, failures = 0;
    double worst = INFINITY;
    for (int n = 1; n <= allocations; ++n) {
      catgs::cuda::CudaRenderer r(c.dev, o);
      counter.fail_at = n;
      const HookScope scope(counter);
      catgs::Yuv420Image out;
      int failed = 0;
      for (std::size_t k = 0; k < c.path.size(); ++k) {
        try {
          draw(r, c.path[k], out);
        } catch (const catgs::OutOfMemoryError&) {
          ++failed;
          draw(r, c.path[k], out);  // must not throw: the renderer is whole
        }
        const double psnr = planes_psnr(out, oracle[k]);
        worst = std::min(worst, psnr);
        if (psnr < min_psnr) ++wrong;
      }
      failures += failed == 1 ? 1 : 0;
    }
    counter.fail_at = 0;
    Row row{"AllocationFaults." + name, "tumblewood_sh2 x13 LOD", "bicycle, 8 poses, a viewport change",
            catgs::pipeline_name(p)};
    row.psnr = worst;
    row.list_ref = allocations;
    row.list_gpu = failures;
    row.pass = allocations >= 10 && failures == allocations && wrong == 0;
    row.note = std::to_string(allocations) + " allocations, each failed in turn: " + std::to_string(failures) +
               " failed once and the renderer went on; " + std::to_string(wrong) + " frames under " +
               fmt_psnr(min_psnr) + " dB";
    add(row);
  }
};

TEST_F(AllocationFaults, ExactFramesEqualANeverFailedRenderers) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  every_failure("exact", Pipeline::exact, false, INFINITY);
}

TEST_F(AllocationFaults, CulledFramesMatchANeverFailedRenderers) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  every_failure("occlusion", Pipeline::exact, true, 50.0);
}

TEST_F(AllocationFaults, CatgsFramesMatchANeverFailedRenderers) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  every_failure("catgs", Pipeline::catgs, false, 35.0);
}

TEST_F(AllocationFaults, ReservedBuffersDrawTheFirstFramesWithoutAllocating) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  const FaultCity& c = fault_city();
  const catgs::RenderOptions o = fault_options(Pipeline::exact, true);
  catgs::BufferShape shape;
  {
    catgs::cuda::CudaRenderer probe(c.dev, o);
    catgs::Yuv420Image out;
    for (std::size_t k = 0; k < 5; ++k) draw(probe, c.path[k], out);
    shape = probe.buffer_shape();
  }
  catgs::cuda::CudaRenderer r(c.dev, o);
  r.reserve_buffers(c.path[0].width, c.path[0].height, shape);
  const catgs::BufferShape held = r.buffer_shape();
  Counter counter;
  int seen = -1;
  {
    const HookScope scope(counter);
    catgs::Yuv420Image out;
    for (std::size_t k = 0; k < 5; ++k) draw(r, c.path[k], out);
    seen = counter.seen;
  }
  Row row{"AllocationFaults.reserved", "tumblewood_sh2 x13 LOD", "bicycle, 5 poses", "exact"};
  row.list_ref = static_cast<long long>(shape.list_entries);
  row.list_gpu = static_cast<long long>(held.list_entries);
  row.pass = seen == 0 && held.gaussians >= shape.gaussians && held.list_entries >= shape.list_entries;
  row.note = std::to_string(seen) + " allocations after the reservation (" + std::to_string(held.gaussians) +
             " slots, " + std::to_string(r.device_buffer_bytes() >> 20) + " MiB)";
  add(row);
}

// A reservation takes the shape it is given, never more than the scene: a server session
// reserves the largest shape its scene's sessions grew to (which holds their growth slack
// already), so slack added again compounded, each new visitor's slots 1.25x the last one's,
// until the GPU refused visitors it had room for (the 101-copy city at 18 sessions).
TEST_F(AllocationFaults, ReservedSlotsAreTheShapeNeverPastTheScene) {
  CATGS_GPU_REQUIRE({"tumblewood_sh2"}, {"mipnerf360_bicycle"});
  const FaultCity& c = fault_city();
  const catgs::RenderOptions o = fault_options(Pipeline::exact, true);
  const std::uint64_t scene_slots = catgs::fm::chunk_count(c.lod->size()) * catgs::fm::kChunkSize;
  const int w = c.path[0].width, h = c.path[0].height;
  // Three quarters of the scene: more than a renderer's first guess (fm::initial_slot_chunks).
  const catgs::BufferShape asked{scene_slots / 4 * 3 / catgs::fm::kChunkSize * catgs::fm::kChunkSize, 0};
  ASSERT_GT(asked.gaussians,
            catgs::fm::initial_slot_chunks(catgs::fm::chunk_count(c.lod->size())) * catgs::fm::kChunkSize)
      << "the reservation must ask for more than the renderer's first guess, or it tests nothing";
  catgs::cuda::CudaRenderer first(c.dev, o), next(c.dev, o), over(c.dev, o);
  first.reserve_buffers(w, h, asked);
  const catgs::BufferShape first_held = first.buffer_shape();
  next.reserve_buffers(w, h, first_held);  // the next visitor at the door
  over.reserve_buffers(w, h, {scene_slots * 4, 0});
  Row row{"AllocationFaults.reserved_slots", "tumblewood_sh2 x13 LOD", "", "exact"};
  row.pass = first_held.gaussians == asked.gaussians && next.buffer_shape().gaussians == first_held.gaussians &&
             over.buffer_shape().gaussians == scene_slots;
  row.note = "asked " + std::to_string(asked.gaussians) + " slots: held " + std::to_string(first_held.gaussians) +
             ", the next " + std::to_string(next.buffer_shape().gaussians) + "; asked 4x the scene's " +
             std::to_string(scene_slots) + ": held " + std::to_string(over.buffer_shape().gaussians);
  add(row);
}

}  // namespace
}  // namespace catgs::gputest
