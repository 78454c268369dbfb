// The CPU reference renderer against the independent brute-force oracle on real scenes, and the
// invariants of its intermediate stages.
#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "brute_force_renderer.h"
#include "colour/yuv420.h"
#include "cpu/cpu_renderer.h"
#include "scene/ply_io.h"
#include "camera/trace.h"
#include "test_data.h"

namespace catgs {
namespace {

std::shared_ptr<const GaussianModel> scene(const std::string& path) { return test::cached_scene(path); }

// A view of the bundled biker: orbiting at 2.5x its extent, y-down scene.
Camera biker_view(const GaussianModel& m, int width, int height, float degrees) {
  GeneratorParams p;
  p.width = width;
  p.height = height;
  p.duration_s = 1.0;
  p.rate_hz = 1.0;
  const Bounds b = m.bounds();
  return make_orbit(b, 1.2f * glm::length(b.extent()), 0.2f * glm::length(b.extent()), degrees, p).back().camera;
}

float max_abs_error(const Image& a, const Image& b) {
  float e = 0.0f;
  for (std::size_t k = 0; k < a.rgb.size(); ++k) e = std::max(e, std::fabs(a.rgb[k] - b.rgb[k]));
  return e;
}

struct Case {
  const char* name;
  bool flowers;  // flowers_sh3 training view, else bundled biker
  int view;      // training view index or orbit degrees
  Pipeline pipeline;
};

class BruteForceTest : public ::testing::TestWithParam<Case> {};

TEST_P(BruteForceTest, CpuRendererMatchesPerPixelOracle) {
  const Case c = GetParam();
  std::shared_ptr<const GaussianModel> m;
  Camera cam;
  if (c.flowers) {
    CATGS_REQUIRE_DATA(scene_path, "scenes/flowers_sh3.ply");
    CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
    m = scene(scene_path);
    cam = load_inria_cameras(cams, 240, 158).at(static_cast<std::size_t>(c.view));
  } else {
    m = scene(test::bundled_scene());
    cam = biker_view(*m, 200, 150, static_cast<float>(c.view));
  }
  cpu::CpuRenderer renderer(m, {c.pipeline, glm::vec3(0.0f), {}});
  Image fast;
  renderer.render(cam, fast);
  const Image slow = test::brute_force_render(*m, cam, c.pipeline == Pipeline::vanilla);
  const double psnr = psnr_rgba8(fast, slow);
  const float err = max_abs_error(fast, slow);
  std::cout << "[ info ] " << c.name << ": PSNR " << psnr << " dB, max abs error " << err << ", render list "
            << renderer.last_stats().render_list_length << "\n";
  EXPECT_GE(psnr, 50.0);
  // Guard against an all-black pair passing: the view must show the scene.
  std::size_t lit = 0;
  for (std::size_t p = 0; p < fast.rgba8.size(); p += 4)
    lit += fast.rgba8[p] + fast.rgba8[p + 1] + fast.rgba8[p + 2] > 30;
  EXPECT_GT(lit, fast.rgba8.size() / 4 / 20);
}

INSTANTIATE_TEST_SUITE_P(RealScenes, BruteForceTest,
                         ::testing::Values(Case{"flowers_view0_vanilla", true, 0, Pipeline::vanilla},
                                           Case{"flowers_view0_exact", true, 0, Pipeline::exact},
                                           Case{"flowers_view90_exact", true, 90, Pipeline::exact},
                                           Case{"biker_0deg_vanilla", false, 0, Pipeline::vanilla},
                                           Case{"biker_0deg_exact", false, 0, Pipeline::exact},
                                           Case{"biker_130deg_exact", false, 130, Pipeline::exact}),
                         [](const auto& param_info) { return std::string(param_info.param.name); });

// The 8-bit conversion every output goes through (renderer.h; the CUDA blend's unorm8 is the
// same expression): clamp, * 255, round half up, and a NaN colour black rather than a
// float-to-integer cast of NaN (undefined behaviour, reported by UBSan in the fuzz build).
TEST(ToUnorm8, ClampsRoundsAndMapsNanToZero) {
  EXPECT_EQ(to_unorm8(0.0f), 0);
  EXPECT_EQ(to_unorm8(1.0f), 255);
  EXPECT_EQ(to_unorm8(0.5f), 128);         // 128.0 exactly: half up
  EXPECT_EQ(to_unorm8(1.4f / 255.0f), 1);  // 1.9 -> 1
  EXPECT_EQ(to_unorm8(-0.25f), 0);
  EXPECT_EQ(to_unorm8(3.0f), 255);
  EXPECT_EQ(to_unorm8(INFINITY), 255);
  EXPECT_EQ(to_unorm8(-INFINITY), 0);
  EXPECT_EQ(to_unorm8(std::nanf("")), 0);
  EXPECT_EQ(to_unorm8(-std::nanf("")), 0);
}

TEST(CpuRenderer, ExactListIsShorterAndImageClose) {
  auto m = scene(test::bundled_scene());
  const Camera cam = biker_view(*m, 640, 480, 40.0f);
  cpu::CpuRenderer vanilla(m, {Pipeline::vanilla, {}, {}}), exact(m, {Pipeline::exact, {}, {}});
  Image iv, ie;
  vanilla.render(cam, iv);
  exact.render(cam, ie);
  const std::size_t lv = vanilla.last_stats().render_list_length, le = exact.last_stats().render_list_length;
  std::cout << "[ info ] biker 640x480: render list vanilla " << lv << ", exact " << le << " ("
            << double(lv) / double(le) << "x shorter); PSNR exact vs vanilla " << psnr_rgba8(iv, ie) << " dB\n";
  EXPECT_LT(le, lv);
  EXPECT_GE(psnr_rgba8(iv, ie), 40.0);
}

TEST(CpuRenderer, StagesKeepTheirInvariants) {
  auto m = scene(test::bundled_scene());
  const Camera cam = biker_view(*m, 320, 240, 200.0f);
  for (Pipeline p : {Pipeline::vanilla, Pipeline::exact}) {
    cpu::CpuRenderer r(m, {p, {}, {}});
    Image img;
    r.render(cam, img);
    const auto& proj = r.projected();
    const auto& list = r.render_list();
    const auto& ranges = r.tile_ranges();
    const auto grid = cpu::TileGrid::of(cam.width, cam.height);
    uint64_t total = 0;
    for (uint32_t t : proj.tiles_touched) total += t;
    ASSERT_EQ(total, list.keys.size());
    ASSERT_TRUE(std::is_sorted(list.keys.begin(), list.keys.end()));
    uint64_t covered = 0;
    for (int tile = 0; tile < grid.tile_count(); ++tile) {
      const glm::uvec2 rg = ranges[static_cast<std::size_t>(tile)];
      covered += rg.y - rg.x;
      for (uint32_t k = rg.x; k < rg.y; ++k) {
        ASSERT_EQ(list.packing.tile_of(list.keys[k]), static_cast<uint32_t>(tile));
        const uint32_t g = list.values[k];
        const fm::TileRect rect = proj.tile_rect[g];
        const int tx = tile % grid.tiles_x, ty = tile / grid.tiles_x;
        ASSERT_TRUE(tx >= rect.x0 && tx < rect.x1 && ty >= rect.y0 && ty < rect.y1);
        if (p == Pipeline::exact) {
          ASSERT_TRUE(
              fm::ellipse_touches_tile(proj.mean2d[g], proj.conic[g], proj.q_max[g], tx, ty, cam.width, cam.height));
        }
      }
    }
    EXPECT_EQ(covered, list.keys.size());
  }
}

TEST(CpuRenderer, BackgroundShowsWhereNothingIs) {
  auto m = scene(test::bundled_scene());
  const Camera cam = biker_view(*m, 160, 120, 0.0f);
  cpu::CpuRenderer r(m, {Pipeline::exact, glm::vec3(1.0f, 0.0f, 1.0f), {}});
  Image img;
  r.render(cam, img);
  // The corner is empty space: pure background.
  EXPECT_EQ(img.rgba8[0], 255);
  EXPECT_EQ(img.rgba8[1], 0);
  EXPECT_EQ(img.rgba8[2], 255);
  const Image oracle = test::brute_force_render(*m, cam, false, glm::vec3(1.0f, 0.0f, 1.0f));
  EXPECT_GE(psnr_rgba8(img, oracle), 50.0);
}

TEST(CpuRenderer, DeterministicAcrossRunsAndReusedBuffers) {
  auto m = scene(test::bundled_scene());
  cpu::CpuRenderer r(m, {});
  Image a, b, small;
  r.render(biker_view(*m, 320, 240, 10.0f), a);
  r.render(biker_view(*m, 64, 48, 10.0f), small);  // shrink, then grow again
  r.render(biker_view(*m, 320, 240, 10.0f), b);
  EXPECT_EQ(a.rgba8, b.rgba8);
  EXPECT_EQ(a.rgb, b.rgb);
}

// A frame in halves (renderer.h begin_yuv420_at / finish_yuv420): the planes of the CPU
// conversion of the rendered frame; a second begin, or a finish without a begin, is refused; a
// begin that threw leaves nothing to finish.
TEST(CpuRenderer, AFrameInHalvesIsTheFrameAndOneAtATime) {
  auto m = scene(test::bundled_scene());
  cpu::CpuRenderer r(m, {});
  const Camera cam = biker_view(*m, 64, 48, 10.0f);
  Image img;
  r.render(cam, img);
  const Yuv420Image want = rgba_to_yuv420_bt709(img.rgba8.data(), 64, 48, 64 * 4);
  Yuv420Image got;
  const Yuv420Target target = got.target(64, 48);
  r.begin_yuv420_at(cam, 0.0, target);
  EXPECT_THROW(r.begin_yuv420_at(cam, 0.0, target), std::logic_error);
  EXPECT_GE(r.finish_yuv420(), 0.0);
  EXPECT_EQ(got.y, want.y);
  EXPECT_EQ(got.u, want.u);
  EXPECT_EQ(got.v, want.v);
  EXPECT_THROW(r.finish_yuv420(), std::logic_error);
  Camera bad = cam;
  bad.t.x = NAN;
  EXPECT_THROW(r.begin_yuv420_at(bad, 0.0, target), std::invalid_argument);
  EXPECT_THROW(r.finish_yuv420(), std::logic_error);
  r.begin_yuv420_at(cam, 0.0, target);  // a frame may begin again
  (void)r.finish_yuv420();
}

TEST(CpuRenderer, RejectsBadCameras) {
  auto m = scene(test::bundled_scene());
  cpu::CpuRenderer r(m, {});
  Image img;
  Camera c = biker_view(*m, 64, 48, 0.0f);
  Camera zero = c;
  zero.width = 0;
  EXPECT_THROW(r.render(zero, img), std::invalid_argument);
  Camera huge = c;
  huge.width = 100000;
  EXPECT_THROW(r.render(huge, img), std::invalid_argument);
  Camera nan = c;
  nan.t.x = NAN;
  EXPECT_THROW(r.render(nan, img), std::invalid_argument);
  EXPECT_THROW(cpu::CpuRenderer(m, {Pipeline::catgs, {}, {}}), std::invalid_argument);
}

// catgs-render's training view of flowers_sh3 must show the flower bed on a lawn: a covered
// frame whose lower third (the lawn) is green-dominant.
TEST(CpuRenderer, FlowersTrainingViewShowsTheLawn) {
  CATGS_REQUIRE_DATA(scene_path, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(cams, "traces/flowers_sh3.cameras.json");
  auto m = scene(scene_path);
  cpu::CpuRenderer r(m, {});
  Image img;
  r.render(load_inria_cameras(cams, 320, 211).at(0), img);
  double sum[3] = {0, 0, 0};
  std::size_t black = 0, n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const uint8_t* p = &img.rgba8[4 * (static_cast<std::size_t>(y) * img.width + x)];
      black += p[0] + p[1] + p[2] < 10;
      if (y > 2 * img.height / 3) {
        for (int c = 0; c < 3; ++c) sum[c] += p[c];
        ++n;
      }
    }
  EXPECT_LT(black, static_cast<std::size_t>(img.width * img.height / 100));
  EXPECT_GT(sum[1], sum[2] * 1.3);  // green over blue
  EXPECT_GT(sum[1] / static_cast<double>(n), 60.0);
}

}  // namespace
}  // namespace catgs
