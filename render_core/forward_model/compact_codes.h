// The compact scene's per-Gaussian codes and their decode (issue 74), shared by the reader
// (scene/compact_file.cpp, which turns a file into the float model both cores draw) and the CUDA
// core (which keeps the codes in device memory in place of the floats and decodes them where a
// Gaussian is pre-processed: cuda/scene_fields.cuh). One function per field, of products and
// sums that never fuse (lod_mul, lod_add: some kernels are built with contraction on), a
// division (IEEE on both) and a sqrt (IEEE on both), so both cores decode the same floats bit for
// bit. The layout of the codes: scene/compact_file.h.
#pragma once

#include <cstdint>

#include "forward_model/lod.h"

namespace catgs::fm {

// One chunk's quantization ranges (float32, 84 bytes): positions (world units), log scales and
// DC coefficients per axis or channel, and the absolute bound of each SH band's coefficients
// (bands 1, 2, 3; 0 past the scene's degree).
struct ChunkRanges {
  float pos_lo[3], pos_hi[3];
  float scale_lo[3], scale_hi[3];
  float dc_lo[3], dc_hi[3];
  float band[3];
};
static_assert(sizeof(ChunkRanges) == 84, "21 floats");

inline constexpr int kCompactShBits = 7;     // a SH rest coefficient's code
inline constexpr int kCompactShLevels = 63;  // code - 63 in [-63, 63]

// The low `bits` of q as the fraction q / (2^bits - 1), taken as q times the float nearest
// 1 / (2^bits - 1) (a product, not a division: the decode runs in pre-processing for every
// Gaussian of a drawn chunk, where divisions cost a measurable share of the frame: RESULTS.md
// "Compact scene").
CATGS_HD float compact_unorm(uint32_t q, int bits) {
  const uint32_t mask = (1u << bits) - 1u;
  return lod_mul(static_cast<float>(q & mask), 1.0f / static_cast<float>(mask));
}

// lo + (hi - lo) t, unfused.
CATGS_HD float compact_lerp(float lo, float hi, float t) { return lod_add(lo, lod_mul(lod_add(hi, -lo), t)); }

// The log scales of an 11-10-11 code (bits 31..21, 20..11, 10..0) in the chunk's ranges.
CATGS_HD void compact_log_scales(uint32_t code, const ChunkRanges& r, float out[3]) {
  out[0] = compact_lerp(r.scale_lo[0], r.scale_hi[0], compact_unorm(code >> 21, 11));
  out[1] = compact_lerp(r.scale_lo[1], r.scale_hi[1], compact_unorm(code >> 11, 10));
  out[2] = compact_lerp(r.scale_lo[2], r.scale_hi[2], compact_unorm(code, 11));
}

// The quaternion (w, x, y, z) of a smallest-three code: bits 31..30 index the largest component,
// the other three in index order in bits 29..20, 19..10, 9..0, each (q / 1023 - 0.5) sqrt(2); the
// largest is sqrt(1 - their squares) (SuperSplat's packRot, scene/quantize.h pack_rotation).
CATGS_HD void compact_rotation(uint32_t code, float q[4]) {
  constexpr float kSqrt2 = 1.41421356237309515f;
  const float small[3] = {lod_mul(lod_add(compact_unorm(code >> 20, 10), -0.5f), kSqrt2),
                          lod_mul(lod_add(compact_unorm(code >> 10, 10), -0.5f), kSqrt2),
                          lod_mul(lod_add(compact_unorm(code, 10), -0.5f), kSqrt2)};
  const unsigned largest = code >> 30;
  const float sum =
      lod_add(lod_add(lod_mul(small[0], small[0]), lod_mul(small[1], small[1])), lod_mul(small[2], small[2]));
  const float rest = lod_add(1.0f, -sum);
  q[largest] = sqrtf(rest > 0.0f ? rest : 0.0f);
  for (unsigned k = 0, s = 0; k < 4; ++k)
    if (k != largest) q[k] = small[s++];
}

// DC coefficient of `channel` from its 8-bit code.
CATGS_HD float compact_dc(uint32_t code, const ChunkRanges& r, int channel) {
  return compact_lerp(r.dc_lo[channel], r.dc_hi[channel], compact_unorm(code, 8));
}

// The SH band (0: band 1, 1: band 2, 2: band 3) of coefficient k >= 1.
CATGS_HD int compact_band_of(int k) { return k < 4 ? 0 : k < 9 ? 1 : 2; }

// SH rest value `index` (0-based over coefficients k >= 1 and channels, channel inner) of a
// Gaussian's codes `codes` (7 bits each, LSB first): (q - 63) x (the float nearest 1 / 63) x its
// band's bound.
CATGS_HD float compact_sh_rest(const uint8_t* codes, int index, const ChunkRanges& r, int k) {
  const int bit = index * kCompactShBits, shift = bit % 8;
  uint32_t two = codes[bit / 8];
  if (shift + kCompactShBits > 8) two |= static_cast<uint32_t>(codes[bit / 8 + 1]) << 8;  // never past the record
  const uint32_t q = (two >> shift) & ((1u << kCompactShBits) - 1u);
  return lod_mul(lod_mul(static_cast<float>(static_cast<int>(q) - kCompactShLevels), 1.0f / kCompactShLevels),
                 r.band[compact_band_of(k)]);
}

}  // namespace catgs::fm
