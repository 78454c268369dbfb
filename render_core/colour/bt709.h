// BT.709 limited-range Y'CbCr from R'G'B' in [0, 1], one formula for the CPU conversion
// (yuv420.cpp) and the CUDA kernel (yuv420_convert.cu), so every code value matches:
//   Y' = 16 + 219 (Kr R + Kg G + Kb B),  Cb = 128 + 224 (B - Y) / (2 (1 - Kb)),
//   Cr = 128 + 224 (R - Y) / (2 (1 - Kr)),  Kr = 0.2126, Kb = 0.0722, Kg = 1 - Kr - Kb
// (ITU-R BT.709-6, item 3.2 and table 3: 8-bit quantisation), in double precision, rounded half
// away from zero and clamped to 0..255. The kernel's file is compiled without FMA contraction, so
// the device evaluates the same expressions as the host.
#pragma once

#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define CATGS_BT709_HD __host__ __device__ __forceinline__
#else
#define CATGS_BT709_HD inline
#endif

namespace catgs::bt709 {

inline constexpr double kKr = 0.2126, kKb = 0.0722, kKg = 1.0 - kKr - kKb;
inline constexpr double kCbScale = 2.0 * (1.0 - kKb), kCrScale = 2.0 * (1.0 - kKr);

// Rounded half away from zero (llround), clamped to a byte.
CATGS_BT709_HD std::uint8_t to_byte(double x) {
  const long long v = llround(x);
  return static_cast<std::uint8_t>(v < 0 ? 0 : (v > 255 ? 255 : v));
}

// The luma weights' sum (the Y of the chroma formulas, before scaling).
CATGS_BT709_HD double luma_of(double r, double g, double b) { return kKr * r + kKg * g + kKb * b; }

// Y' code value of one pixel.
CATGS_BT709_HD std::uint8_t luma(double r, double g, double b) { return to_byte(16.0 + 219.0 * luma_of(r, g, b)); }

// Cb and Cr code values of a chroma sample (4:2:0: the 2x2 block's mean R, G, B).
CATGS_BT709_HD std::uint8_t cb(double r, double g, double b) {
  return to_byte(128.0 + 224.0 * (b - luma_of(r, g, b)) / kCbScale);
}
CATGS_BT709_HD std::uint8_t cr(double r, double g, double b) {
  return to_byte(128.0 + 224.0 * (r - luma_of(r, g, b)) / kCrScale);
}

}  // namespace catgs::bt709
