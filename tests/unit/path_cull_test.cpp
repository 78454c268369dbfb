// The speculative pre-processing's cheap cull (forward_model.h fm::path_misses_image, shared by
// the CPU core and the CUDA stage), worked by hand on a 100 x 100 view (fx = fy = 100, centre 50):
// a small Gaussian at camera-space (x, 0, 10) lands at u = 10 x + 50. It is culled only when it
// lies beyond one same edge at every view of the path where it is in front.
#include <gtest/gtest.h>

#include <vector>

#include "forward_model/forward_model.h"

namespace {

using namespace catgs;

// A view looking down +z from world point -t (R = identity), so camera space is world + t.
fm::View view_at(glm::vec3 t) {
  fm::View v{};
  v.R = glm::mat3(1.0f);
  v.t = t;
  v.fx = v.fy = 100.0f;
  v.cx = v.cy = 50.0f;
  v.width = v.height = 100;
  v.near_plane = 0.1f;
  v.far_plane = 100.0f;
  v.tan_half_fov = glm::vec2(0.5f, 0.5f);
  return v;
}

constexpr float kQMax = 9.0f;
const float kLogScale[3] = {-4.6f, -4.6f, -4.6f};  // scale 0.01: a radius of a pixel or so

bool misses(const glm::vec3& mean, const std::vector<fm::View>& path, float motion_margin = 0.0f) {
  return fm::path_misses_image(
      mean, kLogScale, kQMax, static_cast<int>(path.size()), [&](int k) -> const fm::View& { return path[k]; }, 0.0f,
      0.0f, motion_margin);
}

TEST(PathCull, BeyondOneEdgeAtEveryViewIsCulled) {
  const glm::vec3 left(-20, 0, 10);  // u = -150 at the key view
  EXPECT_TRUE(misses(left, {view_at({0, 0, 0})}));
  EXPECT_TRUE(misses(left, {view_at({0, 0, 0}), view_at({5, 0, 0})})) << "u = -100: still left";
  EXPECT_FALSE(misses(left, {view_at({0, 0, 0}), view_at({20, 0, 0})})) << "on the image at the second view";
  EXPECT_FALSE(misses({-4, 0, 10}, {view_at({0, 0, 0})})) << "u = 10: on the image";
}

TEST(PathCull, LeftThenRightCrossesTheImageAndIsKept) {
  // Beyond the left edge at the key view and beyond the right one at the last: it swept across
  // the image between them, so no one edge holds it out.
  EXPECT_FALSE(misses({-20, 0, 10}, {view_at({0, 0, 0}), view_at({40, 0, 0})}));
  EXPECT_TRUE(misses({0, -20, 10}, {view_at({0, 0, 0}), view_at({40, 0, 0})})) << "above the top edge at both";
}

TEST(PathCull, BehindTheKeyViewIsLeftToTheCallerAndLaterViewsBehindAreSkipped) {
  EXPECT_FALSE(misses({-20, 0, -10}, {view_at({0, 0, 0})}));
  // In front at the key view (left of it), behind the second view: only the key view counts.
  EXPECT_TRUE(misses({-20, 0, 10}, {view_at({0, 0, 0}), view_at({0, 0, -20})}));
}

TEST(PathCull, TheTrailsMotionMarginWidensTheBound) {
  // u = -150 at the key view, -140 at the last: 10 px of motion. A margin of 20 x that widens
  // the radius past 150 px, and the Gaussian is kept; none culls it.
  const std::vector<fm::View> path = {view_at({0, 0, 0}), view_at({1, 0, 0})};
  EXPECT_TRUE(misses({-20, 0, 10}, path, 0.0f));
  EXPECT_TRUE(misses({-20, 0, 10}, path, 10.0f)) << "100 px more: still beyond";
  EXPECT_FALSE(misses({-20, 0, 10}, path, 20.0f));
}

}  // namespace
