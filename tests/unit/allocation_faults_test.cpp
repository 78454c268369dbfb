// An allocation that fails leaves the renderer whole (issue 73; base/allocation_faults.h), on the
// CPU core (its host slot; the CUDA core: tests/gpu/allocation_faults_test.cpp). For every N, a
// renderer whose Nth buffer growth fails draws the frames of a session's start and a viewport
// change; the frame that failed is drawn again, as the server's next pose would be, and from there
// every frame equals the frame of a renderer that never failed (the oracle: the same renderer
// without the fault, side by side).
#include <atomic>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "base/allocation_faults.h"
#include "camera/trace.h"
#include "common/image_io.h"
#include "cpu/cpu_renderer.h"
#include "renderer/renderer.h"
#include "small_city.h"
#include "test_data.h"

namespace catgs {
namespace {

// Counts the allocations the hook is asked about and fails the `fail_at`th (1-based; 0: none).
struct CountingFault {
  std::atomic<int> seen{0};
  int fail_at = 0;
  std::vector<std::string> names;  // what each allocation was, for the failure message
  AllocationFault hook() {
    return [this](std::uint64_t, const char* what) {
      names.emplace_back(what);
      return ++seen == fail_at;
    };
  }
};

// Installs a hook for one scope.
struct FaultScope {
  explicit FaultScope(AllocationFault f) { set_allocation_fault(std::move(f)); }
  ~FaultScope() { set_allocation_fault({}); }
};

// A session's first frames, then a viewport change (a larger view, then back to a smaller one).
std::vector<Camera> session_path(const std::vector<Camera>& views) {
  std::vector<Camera> path;
  for (std::size_t k = 0; k < views.size() && k < 4; ++k) path.push_back(views[k]);
  for (std::size_t k = 4; k < views.size() && k < 7; ++k) {
    const Camera& c = views[k];
    const int w = k == 6 ? c.width / 2 : c.width * 2, h = k == 6 ? c.height / 2 : c.height * 2;
    path.push_back(Camera::from_pose(c.position(), c.orientation(), c.vertical_fov_deg(), w, h));
  }
  return path;
}

struct Outcome {
  int failures = 0;
  double worst_psnr = 1e9;  // of the frames after a failure against the oracle's
  bool all_equal = true;    // rgba8 equal frame for frame
};

// Draws `path` with a renderer made by `make` whose `fail_at`th allocation fails; a frame that
// throws OutOfMemoryError is drawn again. Each frame is compared with `oracle`'s.
template <typename Make>
Outcome run_with_fault(Make make, const std::vector<Camera>& path, const std::vector<Image>& oracle, int fail_at,
                       CountingFault& fault) {
  fault.fail_at = fail_at;
  fault.seen = 0;
  fault.names.clear();
  std::unique_ptr<Renderer> r = make();
  Image out;  // reused, as the server's session does
  Outcome o;
  const FaultScope scope(fault.hook());
  for (std::size_t k = 0; k < path.size(); ++k) {
    try {
      r->render(path[k], out);
    } catch (const OutOfMemoryError& e) {
      ++o.failures;
      EXPECT_NE(std::string(e.what()).find("CPU renderer"), std::string::npos) << e.what();
      r->render(path[k], out);  // the next pose: the renderer must be whole
    }
    o.all_equal = o.all_equal && out.rgba8 == oracle[k].rgba8;
    o.worst_psnr = std::min(o.worst_psnr, psnr_rgba8(out, oracle[k]));
  }
  return o;
}

template <typename Make>
void expect_whole_after_every_failure(Make make, const std::vector<Camera>& path, bool exact_equal, double min_psnr) {
  std::vector<Image> oracle(path.size());
  CountingFault fault;
  int allocations = 0;
  {
    std::unique_ptr<Renderer> r = make();
    const FaultScope scope(fault.hook());
    Image out;
    for (std::size_t k = 0; k < path.size(); ++k) {
      r->render(path[k], out);
      oracle[k] = out;
    }
    allocations = fault.seen;
  }
  ASSERT_GE(allocations, 4) << "the path grows the buffers: a first frame, a larger viewport";
  for (int n = 1; n <= allocations; ++n) {
    const Outcome o = run_with_fault(make, path, oracle, n, fault);
    EXPECT_EQ(o.failures, 1) << "allocation " << n << " failed once";
    const std::string name = n <= static_cast<int>(fault.names.size()) ? fault.names[n - 1] : "?";
    if (exact_equal) {
      EXPECT_TRUE(o.all_equal) << "allocation " << n << " (" << name << ") failed; worst PSNR " << o.worst_psnr;
    }
    EXPECT_GE(o.worst_psnr, min_psnr) << "allocation " << n << " failed";
  }
}

RenderOptions options_of(Pipeline p, bool occlusion) {
  RenderOptions o;
  o.pipeline = p;
  o.lod_error_px = 2.0f;
  o.occlusion_culling = occlusion;
  return o;
}

std::vector<Camera> bundled_views(const GaussianModel& m) {
  GeneratorParams p;
  p.width = 96;
  p.height = 64;
  p.duration_s = 1.0;
  p.rate_hz = 8.0;
  const Bounds b = m.bounds();
  std::vector<Camera> views;
  for (const auto& tc : make_orbit(b, 0.6f * glm::length(b.extent()), 0.1f * glm::length(b.extent()), 90.0f, p))
    views.push_back(tc.camera);
  return views;
}

// The bundled scene (always present): exact and vanilla frames equal the oracle's exactly.
TEST(AllocationFaults, CpuExactAndVanillaFramesAfterAFailureEqualANeverFailedRenderers) {
  const auto scene = test::cached_scene(test::bundled_scene());
  const std::vector<Camera> path = session_path(bundled_views(*scene));
  for (Pipeline p : {Pipeline::exact, Pipeline::vanilla}) {
    SCOPED_TRACE(pipeline_name(p));
    expect_whole_after_every_failure([&] { return std::make_unique<cpu::CpuRenderer>(scene, options_of(p, false)); },
                                     path, true, 1e9);
  }
}

// A real city with occlusion culling, the server's default: a failed frame drops the map, so the
// frame after it draws unculled (the same picture to within the culling's 1/255 a pixel); and the
// catgs pipeline, whose group closes (its next frame a key frame: the picture of an exact frame).
TEST(AllocationFaults, CpuCulledAndSpeculativeFramesAfterAFailureMatchANeverFailedRenderers) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const test::SmallCity& city = test::small_flowers_city();
  const std::vector<Camera> path = session_path(city.views);
  {
    SCOPED_TRACE("exact, occlusion culling");
    expect_whole_after_every_failure(
        [&] { return std::make_unique<cpu::CpuRenderer>(city.lod, options_of(Pipeline::exact, true)); }, path, false,
        50.0);
  }
  {
    SCOPED_TRACE("catgs");
    expect_whole_after_every_failure(
        [&] { return std::make_unique<cpu::SpeculativeRenderer>(city.lod, options_of(Pipeline::catgs, false)); }, path,
        false, 35.0);
  }
}

// Buffers held from the door: after reserve_buffers, a session's first frames ask for no
// allocation beyond what the reservation holds (they fit), and buffer_shape reports it.
TEST(AllocationFaults, CpuReservedBuffersServeTheFirstFramesWithoutGrowing) {
  const auto scene = test::cached_scene(test::bundled_scene());
  const std::vector<Camera> views = bundled_views(*scene);
  cpu::CpuRenderer probe(scene, options_of(Pipeline::exact, false));
  Image out;
  std::uint64_t longest = 0;
  for (const Camera& c : views) {
    probe.render(c, out);
    longest = std::max<std::uint64_t>(longest, probe.last_stats().render_list_length);
  }
  cpu::CpuRenderer r(scene, options_of(Pipeline::exact, false));
  EXPECT_EQ(r.buffer_shape().list_entries, 0u);
  r.reserve_buffers(96, 64, {scene->size(), longest});
  EXPECT_GE(r.buffer_shape().gaussians, scene->size());
  EXPECT_GE(r.buffer_shape().list_entries, longest);
  CountingFault fault;
  fault.fail_at = 1;  // any growth of the renderer's own buffers fails
  const FaultScope scope([&](std::uint64_t, const char* what) {
    return std::strcmp(what, "RGB image") != 0 && std::strcmp(what, "RGBA8 image") != 0 && fault.hook()(0, what);
  });
  Image first;  // the caller's image is the caller's
  for (const Camera& c : views) EXPECT_NO_THROW(r.render(c, first));
  EXPECT_EQ(fault.seen, 0) << (fault.names.empty() ? "" : fault.names[0]);
}

// The environment's soak hook: its grammar, and a probability that fails about that share.
TEST(AllocationFaults, EnvironmentHookParsesAndFailsAboutItsShare) {
  ::setenv("CATGS_FAIL_ALLOCATIONS", "0.25,7", 1);
  AllocationFault f = allocation_fault_from_environment();
  ASSERT_TRUE(f);
  int failed = 0;
  for (int k = 0; k < 4000; ++k) failed += f(1, "x") ? 1 : 0;
  EXPECT_GT(failed, 800);
  EXPECT_LT(failed, 1200);
  for (const char* bad : {"x", "1.5", "-0.1", "0.1,", "0.1,seed", "0.1;3"}) {
    ::setenv("CATGS_FAIL_ALLOCATIONS", bad, 1);
    EXPECT_THROW(allocation_fault_from_environment(), std::invalid_argument) << bad;
  }
  ::setenv("CATGS_FAIL_ALLOCATIONS", "", 1);
  EXPECT_FALSE(allocation_fault_from_environment());
  ::unsetenv("CATGS_FAIL_ALLOCATIONS");
}

}  // namespace
}  // namespace catgs
