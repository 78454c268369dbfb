// BT.709 limited-range code values (render_core/colour/bt709.h, the formula the CPU conversion
// and the CUDA kernel share) against the 8-bit values of ITU-R BT.709's colour bars: black and
// white at 16 / 235 with neutral chroma, and the primaries and secondaries as published (e.g.
// red = Y' 63, Cb 102, Cr 240), and the I420 conversion (colour/yuv420.h) of a frame of them.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <vector>

#include "colour/bt709.h"
#include "colour/yuv420.h"

namespace {

using namespace catgs;

struct Bar {
  const char* name;
  double r, g, b;
  int y, cb, cr;
};

// 100% bars, 8-bit limited range (BT.709 coefficients; e.g. SMPTE RP 219's table of 100% bars).
constexpr std::array<Bar, 8> kBars = {{
    {"white", 1, 1, 1, 235, 128, 128},
    {"yellow", 1, 1, 0, 219, 16, 138},
    {"cyan", 0, 1, 1, 188, 154, 16},
    {"green", 0, 1, 0, 173, 42, 26},
    {"magenta", 1, 0, 1, 78, 214, 230},
    {"red", 1, 0, 0, 63, 102, 240},
    {"blue", 0, 0, 1, 32, 240, 118},
    {"black", 0, 0, 0, 16, 128, 128},
}};

TEST(Bt709, BarsHaveThePublishedCodeValues) {
  for (const Bar& b : kBars) {
    EXPECT_EQ(bt709::luma(b.r, b.g, b.b), b.y) << b.name;
    EXPECT_EQ(bt709::cb(b.r, b.g, b.b), b.cb) << b.name;
    EXPECT_EQ(bt709::cr(b.r, b.g, b.b), b.cr) << b.name;
  }
  EXPECT_EQ(bt709::to_byte(-3.2), 0);
  EXPECT_EQ(bt709::to_byte(300.0), 255);
  EXPECT_EQ(bt709::to_byte(62.5), 63) << "halves away from zero";
}

TEST(Bt709, I420OfAFrameOfBarsHasTheirValues) {
  // Each bar 2x2 pixels wide: every chroma sample sees one bar.
  const int w = 2 * static_cast<int>(kBars.size()), h = 2;
  std::vector<std::uint8_t> rgba(static_cast<std::size_t>(w * h * 4), 255);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Bar& b = kBars[static_cast<std::size_t>(x / 2)];
      std::uint8_t* p = &rgba[static_cast<std::size_t>((y * w + x) * 4)];
      p[0] = static_cast<std::uint8_t>(b.r * 255);
      p[1] = static_cast<std::uint8_t>(b.g * 255);
      p[2] = static_cast<std::uint8_t>(b.b * 255);
    }
  const Yuv420Image img = rgba_to_yuv420_bt709(rgba.data(), w, h, w * 4);
  for (std::size_t k = 0; k < kBars.size(); ++k) {
    EXPECT_EQ(img.y[2 * k], kBars[k].y) << kBars[k].name;
    EXPECT_EQ(img.y[static_cast<std::size_t>(w) + 2 * k + 1], kBars[k].y) << kBars[k].name;
    EXPECT_EQ(img.u[k], kBars[k].cb) << kBars[k].name;
    EXPECT_EQ(img.v[k], kBars[k].cr) << kBars[k].name;
  }
}

}  // namespace
