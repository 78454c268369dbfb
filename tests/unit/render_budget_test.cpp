// Issue 22, finding 6: a scene of giant Gaussians (log-scale 5) lists every Gaussian in every tile;
// the CPU core must refuse the frame with a clear error before allocating its render list, and
// draw ordinary scenes as before.
#include <chrono>
#include <iostream>
#include <memory>
#include <random>
#include <string>

#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

#include "cpu/cpu_renderer.h"
#include "renderer/renderer.h"
#include "scene/ply_io.h"
#include "test_data.h"

namespace catgs {
namespace {

// 5 units back from the origin on -z, looking at it (OpenCV axes: +z forward).
Camera camera_at_origin(int width, int height) {
  return Camera::from_pose(glm::vec3(0.0f, 0.0f, -5.0f), glm::quat(1.0f, 0.0f, 0.0f, 0.0f), 60.0f, width, height);
}

TEST(RenderListBudget, RuleFollowsTheViewport) {
  const RenderListBudget b;
  // 1280x720: 80 x 45 tiles.
  EXPECT_EQ(b.max_entries(1280, 720, 28), b.max_entries_per_tile * 80 * 45);
  EXPECT_EQ(b.max_entries(1281, 720, 28), b.max_entries_per_tile * 81 * 45);
  // 3840x2160: the bytes cap binds before the per-tile one.
  EXPECT_EQ(b.max_entries(3840, 2160, 28), b.max_bytes / 28);
  // Small frames may list min_entries (a whole scene seen in a thumbnail).
  EXPECT_EQ(b.max_entries(64, 48, 28), b.min_entries);
  const RenderListBudget tight{1, 1ull << 40, 0};
  EXPECT_EQ(tight.max_entries(16, 16, 28), 1u);
  EXPECT_NO_THROW(tight.check(1, 16, 16, 28));
  EXPECT_THROW(tight.check(2, 16, 16, 28), RenderBudgetError);
  // Lifted (benchmarks): only the 32-bit tile ranges' limit is left.
  EXPECT_EQ(RenderListBudget::unlimited().max_entries(3840, 2160, 28), 0xffffffffull);
  EXPECT_THROW(RenderListBudget::unlimited().check(1ull << 32, 64, 48, 28), RenderBudgetError);
}

TEST(RenderListBudget, GiantGaussiansFailFastWithAClearError) {
  // 20 k Gaussians x 3600 tiles = 72 M entries > 59 M (16384 a tile at 1280x720): the old core
  // allocated and sorted all of them (about 2 GB with the sort's pairs) before drawing.
  const auto model = test::giant_gaussians(20000, 5.0f);
  for (const Pipeline p : {Pipeline::vanilla, Pipeline::exact}) {
    SCOPED_TRACE(pipeline_name(p));
    RenderOptions options;
    options.pipeline = p;
    cpu::CpuRenderer renderer(model, options);
    Image out;
    const auto start = std::chrono::steady_clock::now();
    try {
      renderer.render(camera_at_origin(1280, 720), out);
      ADD_FAILURE() << "a frame of " << renderer.last_stats().render_list_length << " entries was drawn";
    } catch (const RenderBudgetError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("exceeds the render-list budget of"), std::string::npos) << what;
      EXPECT_NE(what.find("1280x720"), std::string::npos) << what;
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << "[ info ] " << pipeline_name(p) << ": refused after " << s << " s\n";
    // Without the budget this frame took 6.9 s (vanilla) and 9.6 s (exact) and 1.9 GB here; with
    // it, what remains is pre-processing (exact tests each Gaussian's 3600 tiles). Not asserted:
    // wall time depends on the machine's load; the allocation below is what the budget prevents.
    EXPECT_LE(renderer.render_list().keys.capacity(), 1u) << "the list was allocated";
  }
}

TEST(RenderListBudget, OrdinaryScenesAndSmallGiantScenesStillRender) {
  cpu::CpuRenderer biker(test::cached_scene(test::bundled_scene()), RenderOptions{});
  Image out;
  EXPECT_NO_THROW(biker.render(camera_at_origin(640, 360), out));
  // 100 giant Gaussians at 1280x720: 360 k entries, well inside the budget.
  cpu::CpuRenderer few(test::giant_gaussians(100, 5.0f), RenderOptions{});
  ASSERT_NO_THROW(few.render(camera_at_origin(1280, 720), out));
  EXPECT_EQ(few.last_stats().render_list_length, 100u * 80 * 45);
}

}  // namespace
}  // namespace catgs
