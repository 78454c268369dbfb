// The single sort's 32-bit key (forward_model/key_packing.h) against the plain [tile | depth bits]
// key: random pairs never order the other way round and tie only within the stated quantum; and
// on real scenes, what sorting exact lists on it changes in the image (against the plain key's
// image, in the CPU reference, stage by stage).
#include <iostream>
#include <random>

#include <gtest/gtest.h>

#include "camera/trace.h"
#include "cpu/cpu_renderer.h"
#include "forward_model/forward_model.h"
#include "forward_model/key_packing.h"
#include "common/image_io.h"
#include "test_data.h"

namespace catgs {
namespace {

TEST(KeyPacking, NarrowKeysNeverInvertThePlainOrder) {
  std::mt19937 rng(19);
  const uint32_t tiles = 8160;  // 1920x1080
  long long pairs = 0, ties = 0;
  int narrow_ranges = 0;
  // Depth ranges from a sliver (no bit dropped) to 16 binades, and one too wide for 32 bits.
  for (const auto& [near, far] : std::vector<std::pair<float, float>>{
           {1.0f, 1.0000001f}, {0.2f, 3.0f}, {0.01f, 100.0f}, {0.1f, 6000.0f}, {1e-6f, 3e38f}}) {
    const uint32_t lo = fm::float_bits(near), hi = fm::float_bits(far);
    const fm::DepthKeyPacking p = fm::single_sort_packing(lo, hi, tiles);
    if (!fm::is_narrow(p)) {  // only the widest range: the plain key, unchanged
      EXPECT_EQ(near, 1e-6f);
      EXPECT_EQ(p.key64(7, 12345u), (uint64_t{7} << 32) | 12345u);
      continue;
    }
    ++narrow_ranges;
    EXPECT_LE(p.bits + fm::tile_key_bits(tiles), 32);
    EXPECT_LE(p.shift, fm::kMaxDepthShift);
    std::uniform_int_distribution<uint32_t> depth(lo, hi), tile(0, tiles - 1), edge(0, 3);
    auto draw = [&] {
      const uint32_t e = edge(rng);
      return e == 0 ? lo : e == 1 ? hi : depth(rng);
    };
    for (int k = 0; k < 200000; ++k, ++pairs) {
      const uint32_t ta = tile(rng), tb = edge(rng) ? ta : tile(rng), da = draw();
      const uint32_t db = edge(rng) == 0 ? std::min<uint32_t>(hi, da + static_cast<uint32_t>(rng() & 511u))
                                         : draw();  // near neighbours too
      const uint64_t plain_a = (uint64_t{ta} << 32) | da, plain_b = (uint64_t{tb} << 32) | db;
      const uint32_t ka = p.key32(ta, da), kb = p.key32(tb, db);
      ASSERT_EQ(p.tile_of32(ka), ta);
      ASSERT_EQ(uint64_t{ka}, p.key64(ta, da));  // both widths agree where the key is narrow
      if (plain_a < plain_b) ASSERT_LE(ka, kb) << "inverted: depth bits " << da << " vs " << db;
      if (plain_a > plain_b) ASSERT_GE(ka, kb) << "inverted: depth bits " << da << " vs " << db;
      if (ka == kb && plain_a != plain_b) {
        ++ties;
        ASSERT_EQ(ta, tb);
        ASSERT_LT(da > db ? da - db : db - da, 1u << p.shift) << "tied beyond the quantum";
      }
      if (p.shift == 0) ASSERT_EQ(ka == kb, plain_a == plain_b);  // nothing dropped: the plain order
    }
  }
  std::cout << "[ info ] " << pairs << " pairs over " << narrow_ranges << " depth ranges: " << ties
            << " tied by the quantised depth, none inverted\n";
  EXPECT_EQ(narrow_ranges, 4);
  EXPECT_GT(ties, 0);  // the near-neighbour draws must reach the quantum, or this checks little
}

// One frame through the CPU stages, sorted on `packing` (nullptr: the frame's single-sort key).
Image render_sorted(const GaussianModel& m, const Camera& cam, const fm::DepthKeyPacking* packing,
                    fm::DepthKeyPacking* used, std::size_t* entries) {
  const auto grid = cpu::TileGrid::of(cam.width, cam.height);
  cpu::ProjectedGaussians proj;
  cpu::RenderList list;
  cpu::TileRanges ranges;
  cpu::preprocess(m, chunk_bounds_of(m), cam, Pipeline::exact, proj);
  cpu::emit_keys(proj, grid, Pipeline::exact, {}, list);
  *used = packing ? *packing : cpu::single_sort_packing_of(list, grid);
  cpu::sort_render_list(list, *used);
  cpu::identify_tile_ranges(list, grid, ranges);
  Image img;
  cpu::rasterize(proj, list, ranges, grid, glm::vec3(0.0f), img);
  *entries = list.values.size();
  return img;
}

TEST(KeyPacking, QuantisedDepthOrderOnRealScenes) {
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(flowers_cams, "traces/flowers_sh3.cameras.json");
  struct View {
    std::string name;
    std::shared_ptr<const GaussianModel> m;
    Camera cam;
  };
  std::vector<View> views;
  const auto tw = test::cached_scene(tumblewood);
  {
    GeneratorParams p;
    p.width = 1920;
    p.height = 1080;
    p.duration_s = 1.0;
    p.rate_hz = 2.0;
    const Bounds b = tw->bounds();
    views.push_back(
        {"tumblewood orbit 1920x1080", tw,
         make_orbit(b, 0.3f * glm::length(b.extent()), 0.05f * glm::length(b.extent()), 90.0f, p).back().camera});
  }
  const auto fl = test::cached_scene(flowers);
  views.push_back({"flowers view 0 1920x1080", fl, load_inria_cameras(flowers_cams, 1920, 1080).at(0)});
  for (const View& v : views) {
    fm::DepthKeyPacking narrow, plain = fm::plain_key_packing(), used_plain;
    std::size_t ln = 0, lp = 0;
    const Image a = render_sorted(*v.m, v.cam, nullptr, &narrow, &ln);
    const Image b = render_sorted(*v.m, v.cam, &plain, &used_plain, &lp);
    const double psnr = psnr_rgba8(a, b);
    std::cout << "[ info ] " << v.name << ": 32-bit key (" << narrow.bits << " depth bits, shift " << narrow.shift
              << "), " << ln << " entries; image against the plain key's: PSNR " << psnr << " dB\n";
    EXPECT_TRUE(fm::is_narrow(narrow)) << v.name << ": the real depth range should fit";
    EXPECT_EQ(ln, lp);
    EXPECT_GE(psnr, 60.0) << v.name;
  }
}

}  // namespace
}  // namespace catgs
