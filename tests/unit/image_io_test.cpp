// box_downsample (tools/common/image_io.h): the anti-aliased reference of catgs-bench
// --aa-reference. Expected values worked out by hand from the definition (clamp each sample to
// [0, 1], mean of the block, 8 bits as to_unorm8).
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

}  // namespace
}  // namespace catgs
