// box_downsample (tools/common/image_io.h): the anti-aliased reference of catgs-bench
// --aa-reference. Expected values worked out by hand from the definition (clamp each sample to
// [0, 1], mean of the block, 8 bits as to_unorm8). ssim_luma_rgba8: expected values from Wang et
// al. 2004's eq. 13 worked out by hand for one 8x8 window of grey pixels (luma = the grey level).
#include <cmath>
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

#include "common/image_io.h"

namespace catgs {
namespace {

Image float_image(int width, int height, const std::vector<float>& rgb) {
  Image im;
  im.width = width;
  im.height = height;
  im.rgb = rgb;
  im.rgba8.assign(static_cast<std::size_t>(width) * height * 4, 255);
  return im;
}

TEST(BoxDownsample, MeanOfClampedSamplesPerBlock) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // 4 x 2 pixels, two 2 x 2 blocks. Left block: R 0.2, 0.4, 0.6, 0.8 -> 0.5; G 2, -1, 0, 0 ->
  // (1 + 0 + 0 + 0) / 4 = 0.25; B all 1 -> 1. Right block: R 0.1 four times -> 0.1 (25.5 -> 26);
  // G NaN in one sample -> NaN -> 0 in 8 bits; B 0, 0, 0, 0.004 -> 0.001 -> 0.255 -> 0.
  const Image hi = float_image(4, 2,
                               {
                                   0.2f, 2.0f, 1.0f, 0.4f, -1.0f, 1.0f, 0.1f, nan,  0.0f, 0.1f, 0.0f, 0.0f,    // row 0
                                   0.6f, 0.0f, 1.0f, 0.8f, 0.0f,  1.0f, 0.1f, 0.0f, 0.0f, 0.1f, 0.0f, 0.004f,  // row 1
                               });
  const Image lo = box_downsample(hi, 2);
  ASSERT_EQ(lo.width, 2);
  ASSERT_EQ(lo.height, 1);
  EXPECT_NEAR(lo.rgb[0], 0.5f, 1e-6f);
  EXPECT_NEAR(lo.rgb[1], 0.25f, 1e-6f);
  EXPECT_NEAR(lo.rgb[2], 1.0f, 1e-6f);
  EXPECT_NEAR(lo.rgb[3], 0.1f, 1e-6f);
  EXPECT_TRUE(std::isnan(lo.rgb[4]));
  EXPECT_NEAR(lo.rgb[5], 0.001f, 1e-6f);
  const std::vector<uint8_t> want = {128, 64, 255, 255, 26, 0, 0, 255};  // 127.5 + 0.5, 63.75 + 0.5
  EXPECT_EQ(lo.rgba8, want);
}

TEST(BoxDownsample, FactorOneKeepsTheClampedImage) {
  const Image hi = float_image(2, 1, {0.5f, 1.5f, -0.5f, 0.25f, 0.75f, 1.0f});
  const Image lo = box_downsample(hi, 1);
  const std::vector<uint8_t> want = {128, 255, 0, 255, 64, 191, 255, 255};
  EXPECT_EQ(lo.rgba8, want);
  EXPECT_FLOAT_EQ(lo.rgb[1], 1.0f);
}

TEST(BoxDownsample, RefusesSizesThatAreNotMultiples) {
  const Image hi = float_image(3, 2, std::vector<float>(18, 0.5f));
  EXPECT_THROW(box_downsample(hi, 2), std::invalid_argument);
  EXPECT_THROW(box_downsample(hi, 0), std::invalid_argument);
  Image no_float = hi;
  no_float.rgb.clear();
  EXPECT_THROW(box_downsample(no_float, 1), std::invalid_argument);
}

// An 8-bit grey image, `value(x, y)` at each pixel.
template <typename F>
Image grey_image(int width, int height, F value) {
  Image im;
  im.width = width;
  im.height = height;
  im.rgba8.assign(static_cast<std::size_t>(width) * height * 4, 255);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c) im.rgba8[4 * (static_cast<std::size_t>(y) * width + x) + c] = value(x, y);
  return im;
}

constexpr double kC1 = 6.5025, kC2 = 58.5225;  // (0.01 * 255)^2, (0.03 * 255)^2

TEST(SsimLuma, OneWindowOfAShiftedCheckerboard) {
  // 0/200 checkerboard: mean 100, variance 10000. +10: mean 110, the same variance and a
  // covariance of 10000, so only the luminance term is below 1.
  const Image a = grey_image(8, 8, [](int x, int y) { return (x + y) % 2 ? 200 : 0; });
  const Image b = grey_image(8, 8, [](int x, int y) { return (x + y) % 2 ? 210 : 10; });
  const double expected = (2 * 100.0 * 110 + kC1) / (100.0 * 100 + 110.0 * 110 + kC1);
  EXPECT_NEAR(ssim_luma_rgba8(a, b), expected, 1e-9);
  EXPECT_DOUBLE_EQ(ssim_luma_rgba8(a, a), 1.0);
}

TEST(SsimLuma, OneWindowOfAHalvedContrast) {
  // 0/200 against 0/100: means 100 and 50, variances 10000 and 2500, covariance 5000.
  const Image a = grey_image(8, 8, [](int x, int y) { return (x + y) % 2 ? 200 : 0; });
  const Image b = grey_image(8, 8, [](int x, int y) { return (x + y) % 2 ? 100 : 0; });
  const double expected =
      (2 * 100.0 * 50 + kC1) * (2 * 5000.0 + kC2) / ((100.0 * 100 + 50.0 * 50 + kC1) * (10000.0 + 2500 + kC2));
  EXPECT_NEAR(ssim_luma_rgba8(a, b), expected, 1e-9);
}

TEST(SsimLuma, MeanOverWindowsEveryFourPixels) {
  // 12x8: windows at x = 0 and 4. Left 4 columns flat 50 in both images; the rest a 0/200
  // checkerboard, +10 in b. Window 0: its left half flat 50, its right half the checkerboard;
  // window 1 is all checkerboard, the shifted case above.
  auto av = [](int x, int y) { return x < 4 ? 50 : ((x + y) % 2 ? 200 : 0); };
  auto bv = [](int x, int y) { return x < 4 ? 50 : ((x + y) % 2 ? 210 : 10); };
  const Image a = grey_image(12, 8, av), b = grey_image(12, 8, bv);
  // Window 0: 32 pixels of 50 in both, 16 of 0 / 10 and 16 of 200 / 210.
  const double mx = (32 * 50.0 + 16 * 200.0) / 64, my = (32 * 50.0 + 16 * 10.0 + 16 * 210.0) / 64;
  const double sxx = (32 * 2500.0 + 16 * 40000.0) / 64, syy = (32 * 2500.0 + 16 * 100.0 + 16 * 44100.0) / 64;
  const double sxy = (32 * 2500.0 + 16 * 0.0 + 16 * 200.0 * 210) / 64;
  const double vx = sxx - mx * mx, vy = syy - my * my, cov = sxy - mx * my;
  const double w0 = (2 * mx * my + kC1) * (2 * cov + kC2) / ((mx * mx + my * my + kC1) * (vx + vy + kC2));
  const double w1 = (2 * 100.0 * 110 + kC1) / (100.0 * 100 + 110.0 * 110 + kC1);
  EXPECT_NEAR(ssim_luma_rgba8(a, b), (w0 + w1) / 2, 1e-9);
}

TEST(SsimLuma, RefusesDifferentOrTinyImages) {
  const Image a = grey_image(8, 8, [](int, int) { return 0; });
  EXPECT_THROW(ssim_luma_rgba8(a, grey_image(10, 8, [](int, int) { return 0; })), std::invalid_argument);
  const Image tiny = grey_image(6, 6, [](int, int) { return 0; });
  EXPECT_THROW(ssim_luma_rgba8(tiny, tiny), std::invalid_argument);
}

}  // namespace
}  // namespace catgs
