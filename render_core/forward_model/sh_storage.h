// How both render cores store SH coefficients: IEEE 754 binary16 ("half"). The CUDA core keeps
// the scene's SH array in half precision in device memory (DeviceScene) and widens each
// coefficient as it reads it; the CPU reference rounds each float coefficient to half as it reads
// it (HalfRoundedSh), so both evaluate colour from the same numbers.
//
// Why: a visible Gaussian's SH (27 floats at degree 2, 48 at degree 3) is most of the bytes that
// pre-processing and a catgs sub-frame's features read from DRAM, and those kernels are bound by
// DRAM (docs/history/render_core_precision.md, "SH in half precision"); half halves them and the
// scene's largest array.
//
// Precision: round to nearest, ties to even, 11 significant bits, so each coefficient's relative
// error is at most 2^-11; |x| < 2^-14 is kept as a subnormal (absolute error at most 2^-25). The
// colour of a Gaussian changes by at most 2^-11 * sum_k |Y_k(dir)| |c_k| per channel (Y_k the SH
// basis); sh_storage_test and docs/history/render_core_precision.md state what this is on the
// real scenes. Magnitudes at or
// beyond 65520 (which round to infinity in IEEE) saturate at the largest finite half, 65504,
// instead: an absurd coefficient in a file must not make a colour inf or NaN (inf * 0). A NaN
// coefficient (no reader lets one in, but a model can be handed to a core straight from memory)
// is stored as 0, so it cannot turn its Gaussian's pixels into NaN, black after the 8-bit
// conversion (issue 49).
// Source of the format: IEEE 754-2008 sec. 3.6 (binary16: 1 sign, 5 exponent bits with bias 15,
// 10 fraction bits).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

namespace catgs::fm {

// binary16 bits of `f`, rounded to nearest even, saturating at +/-65504; NaN -> 0 (+-0).
inline uint16_t half_bits(float f) {
  uint32_t x;
  std::memcpy(&x, &f, sizeof x);
  const uint32_t sign = (x >> 16) & 0x8000u;
  const uint32_t ax = x & 0x7fffffffu;
  if (ax > 0x7f800000u) return static_cast<uint16_t>(sign);             // NaN: 0, see above
  if (ax >= 0x477ff000u) return static_cast<uint16_t>(sign | 0x7bffu);  // >= 65520 (and inf): saturate
  if (ax < 0x38800000u) {  // below 2^-14: a subnormal half m * 2^-24, m in [0, 1024]
    // The scaling by 2^24 is exact, and rint rounds to nearest even; m = 1024 is the smallest
    // normal half, whose bits follow on.
    const float m = std::rint(std::fabs(f) * 16777216.0f);
    return static_cast<uint16_t>(sign | static_cast<uint32_t>(m));
  }
  // Normal: rebias the exponent (127 -> 15), keep 10 fraction bits, round the 13 dropped ones.
  const uint32_t mant = ax & 0x7fffffu;
  uint32_t h = (((ax >> 23) - 112u) << 10) | (mant >> 13);
  const uint32_t rest = mant & 0x1fffu;
  if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) ++h;  // a carry into the exponent is right
  return static_cast<uint16_t>(sign | h);
}

// The float value of binary16 bits `h` (exact: every half is a float).
inline float half_to_float(uint16_t h) {
  const uint32_t sign = static_cast<uint32_t>(h & 0x8000u) << 16;
  const uint32_t e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
  if (e == 0) return (sign ? -1.0f : 1.0f) * std::ldexp(static_cast<float>(m), -24);
  const uint32_t bits = e == 31 ? (sign | 0x7f800000u | (m << 13)) : (sign | ((e + 112u) << 23) | (m << 13));
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

inline float round_to_half(float f) { return half_to_float(half_bits(f)); }

// The CPU reference's reader of one Gaussian's SH coefficients (forward_model.h sh_to_color_from):
// coefficient j of its K x 3 floats, rounded to half as the CUDA core stores it.
struct HalfRoundedSh {
  const float* sh;
  float operator()(int j) const { return round_to_half(sh[j]); }
};

}  // namespace catgs::fm
