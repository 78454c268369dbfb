// Fixed-point packing shared by the lossy scene formats we write and read: SuperSplat compressed
// PLY (ply_io.h) and our compact scene (compact_file.h).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace catgs::quant {

// t in [0, 1] (clamped) to the nearest of the 2^bits levels q / (2^bits - 1).
inline uint32_t unorm_bits(float t, int bits) {
  const float mask = static_cast<float>((1u << bits) - 1u);
  return static_cast<uint32_t>(std::lround(std::clamp(t, 0.0f, 1.0f) * mask));
}

// The low `bits` of v as the fraction q / (2^bits - 1).
inline float unorm(uint32_t v, int bits) {
  const uint32_t mask = (1u << bits) - 1u;
  return static_cast<float>(v & mask) / static_cast<float>(mask);
}

// (v - lo) / (hi - lo), 0 for an empty range.
inline float normalized(float v, float lo, float hi) { return hi > lo ? (v - lo) / (hi - lo) : 0.0f; }

// Smallest-three quaternion in 32 bits, over (q0, q1, q2, q3) in the caller's order (INRIA and
// GaussianModel: w, x, y, z), as SuperSplat's packRot writes it and PlayCanvas's engine reads it:
// bits 31..30 index the largest |component| (made positive by negating the quaternion, the same
// rotation), the other three follow in index order in bits 29..20, 19..10, 9..0, each
// q / 1023 - 0.5 scaled by sqrt(2) (they lie in [-1/sqrt(2), 1/sqrt(2)]: steps of sqrt(2) / 1023).
// The quaternion is normalised first; a zero one packs as the identity.
inline uint32_t pack_rotation_normalised(const float* q_in) {
  float q[4], len2 = 0.0f;
  for (int k = 0; k < 4; ++k) len2 += q_in[k] * q_in[k];
  const float len = std::sqrt(len2);
  int largest = 0;
  for (int k = 0; k < 4; ++k) {
    q[k] = len > 0.0f ? q_in[k] / len : (k == 0 ? 1.0f : 0.0f);
    if (std::fabs(q[k]) > std::fabs(q[largest])) largest = k;
  }
  const float sign = q[largest] < 0.0f ? -1.0f : 1.0f;
  uint32_t packed = static_cast<uint32_t>(largest) << 30;
  int shift = 20;
  for (int k = 0; k < 4; ++k) {
    if (k == largest) continue;
    packed |= unorm_bits(sign * q[k] * std::sqrt(0.5f) + 0.5f, 10) << shift;
    shift -= 10;
  }
  return packed;
}

// pack_rotation's inverse: the largest component is sqrt(1 - the others' squares).
inline void unpack_rotation(uint32_t packed, float* q) {
  const float norm = std::sqrt(2.0f);
  const float small[3] = {(unorm(packed >> 20, 10) - 0.5f) * norm, (unorm(packed >> 10, 10) - 0.5f) * norm,
                          (unorm(packed, 10) - 0.5f) * norm};
  const unsigned largest = packed >> 30;
  q[largest] = std::sqrt(std::fmax(0.0f, 1.0f - (small[0] * small[0] + small[1] * small[1] + small[2] * small[2])));
  for (unsigned k = 0, s = 0; k < 4; ++k)
    if (k != largest) q[k] = small[s++];
}

// pack_rotation_normalised, except that a quaternion some code decodes to (unpack_rotation) bit for
// bit packs as that code: a decoded rotation written again (a compressed PLY or compact scene
// read, then written in the compact form) keeps its code, so nothing the source held is lost
// (issue 74). Re-packing a decoded quaternion can land elsewhere otherwise: it is not of unit
// length once the small components are rounded (its length is renormalised away), and the
// rounding can leave a small component larger than the recomputed largest one (another index).
// Here each index is tried with the components as they are; where none decodes back, the
// normalised packing.
inline uint32_t pack_rotation(const float* q_in) {
  for (uint32_t largest = 0; largest < 4; ++largest) {
    if (!(q_in[largest] >= 0.0f)) continue;  // a decode's largest component is sqrt(...) >= 0
    uint32_t packed = largest << 30;
    int shift = 20;
    for (uint32_t k = 0; k < 4; ++k) {
      if (k == largest) continue;
      packed |= unorm_bits(q_in[k] * std::sqrt(0.5f) + 0.5f, 10) << shift;
      shift -= 10;
    }
    float back[4];
    unpack_rotation(packed, back);
    if (back[0] == q_in[0] && back[1] == q_in[1] && back[2] == q_in[2] && back[3] == q_in[3]) return packed;
  }
  return pack_rotation_normalised(q_in);
}

// Three values of [0, 1] in 11, 10 and 11 bits (bits 31..21, 20..11, 10..0), compressed PLY's
// packing of positions and log scales.
inline uint32_t pack_11_10_11(const float t[3]) {
  return (unorm_bits(t[0], 11) << 21) | (unorm_bits(t[1], 10) << 11) | unorm_bits(t[2], 11);
}
inline void unpack_11_10_11(uint32_t packed, float t[3]) {
  t[0] = unorm(packed >> 21, 11);
  t[1] = unorm(packed >> 11, 10);
  t[2] = unorm(packed, 11);
}

}  // namespace catgs::quant
