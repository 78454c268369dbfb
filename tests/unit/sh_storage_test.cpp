// SH stored in half precision (forward_model/sh_storage.h): the float <-> binary16 conversions
// against the compiler's own _Float16 (an independent implementation of IEEE 754 binary16), and
// the colour error the rounding causes on the real scenes against the bound the header states,
// worked out in double precision with the brute-force oracle's SH basis.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <limits>

#include <gtest/gtest.h>

#include "brute_force_renderer.h"
#include "forward_model/forward_model.h"
#include "forward_model/sh_storage.h"
#include "test_data.h"

namespace catgs {
namespace {

float from_bits(uint32_t u) {
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

#if defined(__FLT16_MAX__)
uint16_t compiler_half_bits(float f) {
  const _Float16 h = static_cast<_Float16>(f);
  uint16_t u;
  std::memcpy(&u, &h, sizeof u);
  return u;
}

TEST(ShStorage, HalfBitsMatchTheCompilersBinary16) {
  // Every float pattern in steps of a prime (all exponents and many fractions), and the floats
  // at, and one ulp either side of, each midpoint between neighbouring halves (where rounding
  // to nearest even decides).
  std::size_t checked = 0;
  auto check = [&](float f) {
    if (std::isnan(f)) {  // stored as zero (sh_storage.h)
      EXPECT_EQ(fm::half_to_float(fm::half_bits(f)), 0.0f);
      return;
    }
    if (std::fabs(f) >= 65520.0f) {  // IEEE rounds to infinity; we saturate (sh_storage.h)
      EXPECT_EQ(fm::half_bits(f), f > 0 ? 0x7bffu : 0xfbffu) << f;
      return;
    }
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    ASSERT_EQ(fm::half_bits(f), compiler_half_bits(f)) << "float bits " << std::hex << bits;
    ++checked;
  };
  for (uint64_t u = 0; u <= 0xffffffffull; u += 65521u) check(from_bits(static_cast<uint32_t>(u)));
  for (uint32_t h = 0; h < 0x7bffu; ++h) {
    const double a = fm::half_to_float(static_cast<uint16_t>(h)), b = fm::half_to_float(static_cast<uint16_t>(h + 1));
    const float mid = static_cast<float>(0.5 * (a + b));  // exact: halves have 11 bits
    for (float f : {mid, std::nextafter(mid, 0.0f), std::nextafter(mid, 1e30f)}) {
      check(f);
      check(-f);
    }
  }
  EXPECT_GT(checked, 200000u);
}

TEST(ShStorage, HalfToFloatMatchesTheCompilerForEveryHalf) {
  for (uint32_t h = 0; h <= 0xffffu; ++h) {
    _Float16 x;
    const uint16_t bits = static_cast<uint16_t>(h);
    std::memcpy(&x, &bits, sizeof x);
    const float want = static_cast<float>(x), got = fm::half_to_float(bits);
    if (std::isnan(want)) {
      EXPECT_TRUE(std::isnan(got)) << h;
    } else {
      ASSERT_EQ(std::memcmp(&want, &got, sizeof want), 0) << "half bits " << h << ": " << want << " vs " << got;
    }
  }
}
#endif

TEST(ShStorage, SaturatesInsteadOfInfinity) {
  EXPECT_EQ(fm::round_to_half(1e30f), 65504.0f);
  EXPECT_EQ(fm::round_to_half(-std::numeric_limits<float>::infinity()), -65504.0f);
  EXPECT_EQ(fm::round_to_half(65519.0f), 65504.0f);
  EXPECT_EQ(fm::round_to_half(1.0f + 1.0f / 4096.0f), 1.0f);                   // tie, to even
  EXPECT_EQ(fm::round_to_half(1.0f + 3.0f / 2048.0f), 1.0f + 2.0f / 1024.0f);  // tie, to even
  EXPECT_EQ(fm::round_to_half(std::ldexp(1.0f, -25)), 0.0f);                   // tie below the least subnormal
  EXPECT_EQ(fm::round_to_half(std::ldexp(3.0f, -25)), std::ldexp(2.0f, -24));  // tie, to even
}

// Directions: the 26 neighbours of the cube's centre, normalised.
std::vector<glm::dvec3> directions() {
  std::vector<glm::dvec3> d;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z)
        if (x || y || z) d.push_back(glm::normalize(glm::dvec3(x, y, z)));
  return d;
}

// Over every Gaussian of the scene and 26 directions: the colour from half-rounded coefficients
// (what both cores evaluate) against the colour from the file's floats. The rounding error of
// each coefficient is at most 2^-11 of it (2^-25 absolute below 2^-14), so the colour moves by at
// most the sum of those times |Y_k|; the renderer's float evaluation adds a few ulps. Reports the
// largest error: a pixel is a convex combination of colours (weights sum to at most 1), so no
// pixel moves by more.
void check_scene_colour_error(const std::string& path) {
  const auto m = test::cached_scene(path);
  const int K = m->sh_coeffs();
  const auto dirs = directions();
  double worst = 0.0, worst_bound = 0.0;
  for (std::size_t i = 0; i < m->size(); ++i) {
    const float* sh = &m->sh[static_cast<std::size_t>(K) * 3 * i];
    for (const glm::dvec3& d : dirs) {
      double y[16];
      test::sh_basis(d, y);
      const glm::vec3 dir(d);
      const glm::vec3 full = fm::sh_to_color(m->sh_degree, sh, dir);
      const glm::vec3 half = fm::sh_to_color_from(m->sh_degree, fm::HalfRoundedSh{sh}, dir);
      for (int ch = 0; ch < 3; ++ch) {
        double bound = 0.0, magnitude = 0.0;
        for (int k = 0; k < K; ++k) {
          const double c = std::fabs(static_cast<double>(sh[3 * k + ch]));
          bound += std::fabs(y[k]) * std::max(c * std::ldexp(1.0, -11), std::ldexp(1.0, -25));
          magnitude += std::fabs(y[k]) * c;
        }
        const double err = std::fabs(static_cast<double>(half[ch]) - static_cast<double>(full[ch]));
        const double float_eval = 4.0 * (magnitude + 0.5) * std::numeric_limits<float>::epsilon();
        ASSERT_LE(err, bound + float_eval) << path << " Gaussian " << i << " channel " << ch;
        worst = std::max(worst, err);
        worst_bound = std::max(worst_bound, bound);
      }
    }
  }
  std::cout << "[ info ] " << path << ": " << m->size() << " Gaussians, SH degree " << m->sh_degree
            << ": largest colour error of half-precision SH " << worst << " (bound " << worst_bound
            << "), so every pixel within " << worst
            << " of the float-SH render (PSNR >= " << 20.0 * std::log10(1.0 / std::max(worst, 1e-12)) << " dB)\n";
  EXPECT_GT(worst, 0.0);  // the rounding must reach the colour, or this checks nothing
}

TEST(ShStorage, ColourErrorOnRealScenesWithinTheBound) {
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  CATGS_REQUIRE_DATA(tumblewood, "scenes/tumblewood_sh2.ply");
  check_scene_colour_error(flowers);
  check_scene_colour_error(tumblewood);
  check_scene_colour_error(test::bundled_scene());
}

}  // namespace
}  // namespace catgs
