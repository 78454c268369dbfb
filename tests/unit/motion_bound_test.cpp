// The motion bound M (forward_model/motion_bound.h, issue 36): the bins, the quantile against a
// sort of the motions themselves, and the CPU core's M on a real scene against motions computed
// here mean by mean.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/chunk_bounds.h"
#include "forward_model/motion_bound.h"
#include "test_data.h"

namespace catgs {
namespace {

TEST(MotionBound, BinsQuarterPixelsUpTo64) {
  EXPECT_EQ(fm::motion_bin(0.0f), 0);
  EXPECT_EQ(fm::motion_bin(0.2499f), 0);
  EXPECT_EQ(fm::motion_bin(0.25f), 1);
  EXPECT_EQ(fm::motion_bin(16.0f), 64);
  EXPECT_EQ(fm::motion_bin(63.99f), fm::kMotionBins - 2);
  EXPECT_EQ(fm::motion_bin(64.0f), fm::kMotionBins - 1);
  EXPECT_EQ(fm::motion_bin(std::numeric_limits<float>::infinity()), fm::kMotionBins - 1);
  EXPECT_EQ(fm::motion_bin(std::nanf("")), fm::kMotionBins - 1);
}

// The k-th smallest of the motions, k = ceil(q n): what the histogram's quantile rounds up.
float sorted_quantile(std::vector<float> motions, float q) {
  std::sort(motions.begin(), motions.end());
  auto k = static_cast<std::size_t>(std::ceil(static_cast<double>(q) * static_cast<double>(motions.size())));
  return motions[std::max<std::size_t>(k, 1) - 1];
}

TEST(MotionBound, QuantileIsTheSortedMotionRoundedUpToItsBin) {
  std::mt19937 rng(36);
  std::lognormal_distribution<float> motion(1.0f, 1.2f);  // most below 16 px, a tail past 64
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<float> m(1 + rng() % 5000);
    for (float& v : m) v = motion(rng);
    uint32_t counts[fm::kMotionBins] = {};
    for (float v : m) ++counts[fm::motion_bin(v)];
    const float max_motion = *std::max_element(m.begin(), m.end());
    for (float q : {0.1f, 0.5f, 0.9f, 0.99f}) {
      const float want = sorted_quantile(m, q), got = fm::motion_quantile(counts, max_motion, q);
      EXPECT_GE(got, want) << "trial " << trial << " q " << q;  // conservative
      EXPECT_LE(got, max_motion);
      if (want < static_cast<float>(fm::kMotionBinnedPixels))
        EXPECT_LT(got - want, 1.0f / fm::kMotionBinsPerPixel + 1e-5f) << "trial " << trial << " q " << q;
      else
        EXPECT_EQ(got, max_motion);  // the open bin: the maximum, as the paper's M
    }
    EXPECT_EQ(fm::motion_quantile(counts, max_motion, 1.0f), max_motion);
  }
  const uint32_t none[fm::kMotionBins] = {};
  EXPECT_EQ(fm::motion_quantile(none, 0.0f, 0.5f), 0.0f);
}

// The CPU core's M on a real scene: every mean on the key image deeper than d, projected here.
TEST(MotionBound, CpuQuantileMatchesMeansProjectedHere) {
  const auto m = test::cached_scene(test::bundled_scene());
  GeneratorParams p;
  p.width = 320;
  p.height = 180;
  p.duration_s = 0.5;
  p.rate_hz = 60.0;
  const Bounds b = m->bounds();
  const Trace t = make_orbit(b, 0.6f * glm::length(b.extent()), 0.1f * glm::length(b.extent()), 90.0f, p);
  const std::vector<fm::ChunkBounds> chunks = fm::chunk_bounds(*m);
  const float d = 0.4f;
  for (std::size_t k = 0; k + 1 < t.size(); k += 7) {
    const Camera &a = t[k].camera, &c = t[k + 1].camera;
    std::vector<float> motions;
    for (std::size_t i = 0; i < m->size(); ++i) {
      const glm::vec3 x(m->means[3 * i], m->means[3 * i + 1], m->means[3 * i + 2]);
      const glm::vec3 pa = a.R * x + a.t, pc = c.R * x + c.t;
      if (!(pa.z > d) || !(pc.z > a.near_plane)) continue;
      const glm::vec2 ua(a.fx * pa.x / pa.z + a.cx, a.fy * pa.y / pa.z + a.cy);
      if (ua.x < 0 || ua.y < 0 || ua.x > static_cast<float>(a.width) || ua.y > static_cast<float>(a.height)) continue;
      motions.push_back(glm::length(glm::vec2(c.fx * pc.x / pc.z + c.cx, c.fy * pc.y / pc.z + c.cy) - ua));
    }
    ASSERT_GT(motions.size(), 1000u) << "view " << k << " should see most of the biker";
    const float max_motion = *std::max_element(motions.begin(), motions.end());
    EXPECT_EQ(cpu::screen_motion_bound(*m, chunks, a, c, d), max_motion);
    for (float q : {0.5f, 0.95f}) {
      const float want = sorted_quantile(motions, q), got = cpu::screen_motion_bound(*m, chunks, a, c, d, q);
      EXPECT_GE(got, want) << "view " << k << " q " << q;
      EXPECT_LT(got - want, 1.0f / fm::kMotionBinsPerPixel + 1e-5f) << "view " << k << " q " << q;
    }
  }
}

}  // namespace
}  // namespace catgs
