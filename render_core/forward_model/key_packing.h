// How a render-list sort key holds a Gaussian's view depth, shared by the CPU reference's sort
// and the CUDA core's key emission, sort and tile ranges, so both order a list the same way.
//
// The plain key is [tile id | the 32 IEEE bits of the view depth] (forward_model.h render_key):
// view depths of listed Gaussians are positive floats, whose bit patterns increase with the value.
// The single radix sort of exact and vanilla frames uses a 32-bit key instead where it can
// (single_sort_packing),
//   [tile id | (depth bits - base) >> shift],
// with base the smallest listed depth's bits and at most 32 - tile_key_bits(tiles) depth bits (19
// at 1920x1080), shift chosen so the frame's listed depth range fits them. A 32-bit key halves
// the sort's key traffic against a 64-bit one and needs one radix pass fewer (4 of 8 bits, not 5).
// The price: depths whose bit patterns agree above `shift` (a relative depth difference below
// about 2^(shift-23), e.g. 3e-5 for a range of 16 binades) tie, and ties keep Gaussian index
// order (the sorts are stable and emission runs in index order), where the plain key orders them
// by depth. The CPU reference sorts on the same key, so both cores draw the same list; what the
// coarser order changes in the image is measured in docs/history/render_core_sort_and_keys.md
// ("32-bit sort keys; huge Gaussians a block each").
// When the range fits without dropping bits (shift = 0) the list equals the plain key's.
#pragma once

#include <cstdint>

#if defined(__CUDACC__)
#define CATGS_KEY_HD __host__ __device__ __forceinline__
#else
#define CATGS_KEY_HD inline
#endif

namespace catgs::fm {

// Key bits the tile id needs for a grid of `tiles` tiles, the sentinel id `tiles` included.
constexpr int tile_key_bits(uint32_t tiles) {
  int bits = 0;
  while (bits < 32 && (tiles >> bits) != 0u) ++bits;
  return bits;
}
static_assert(tile_key_bits(8160) == 13, "1920x1080 has 120 x 68 tiles");
static_assert(tile_key_bits(65535) == 16 && tile_key_bits(65536) == 17, "sentinel needs a bit");

struct DepthKeyPacking {
  uint32_t base = 0;  // depth bits subtracted first
  int bits = 32;      // depth bits kept in the key (0: the tile id alone)
  int shift = 0;      // low bits of (depth bits - base) dropped

  CATGS_KEY_HD uint32_t depth_mask() const { return bits >= 32 ? 0xffffffffu : (1u << bits) - 1u; }
  // The depth's part of the key. Depths outside the range clamp to its ends (only the
  // sentinel's 0xffffffff does, by design: it sorts last).
  CATGS_KEY_HD uint32_t depth_code(uint32_t depth_bits) const {
    uint32_t rel = depth_bits >= base ? depth_bits - base : 0u;
    rel = shift >= 32 ? 0u : rel >> shift;
    return rel < depth_mask() ? rel : depth_mask();
  }
  CATGS_KEY_HD uint64_t key64(uint32_t tile, uint32_t depth_bits) const {
    return (static_cast<uint64_t>(tile) << bits) | depth_code(depth_bits);
  }
  // Needs tile_key_bits(tiles) + bits <= 32 (single_sort_packing makes it so).
  CATGS_KEY_HD uint32_t key32(uint32_t tile, uint32_t depth_bits) const {
    return bits >= 32 ? depth_code(depth_bits) : (tile << bits) | depth_code(depth_bits);
  }
  CATGS_KEY_HD uint32_t tile_of(uint64_t key) const { return static_cast<uint32_t>(key >> bits); }
  CATGS_KEY_HD uint32_t tile_of32(uint32_t key) const { return bits >= 32 ? 0u : key >> bits; }
};

// The plain 64-bit key [tile | depth bits].
constexpr DepthKeyPacking plain_key_packing() { return {0u, 32, 0}; }
// The tile id alone (32-bit; the depth-first sort's second pass, which keeps the depth order).
constexpr DepthKeyPacking tile_only_packing() { return {0u, 0, 0}; }

// Low depth bits the 32-bit key may drop: ties then join depths within 2^(8 - 23) = 3.1e-5 of
// each other, relatively (a float's 23 fraction bits). A frame that would need more falls back to
// the plain 64-bit key.
inline constexpr int kMaxDepthShift = 8;

// The key of a frame's single radix sort, for listed depths with bit patterns in [low, high] on a
// grid of `tiles` tiles: the 32-bit [tile | (depth bits - low) >> shift] when the range fits
// 32 - tile_key_bits(tiles) bits with shift <= kMaxDepthShift (at 1920x1080: 19 bits, so depth
// ranges up to 2^27 patterns, 16 binades, e.g. 0.1 to 6500 units), else the plain key. The
// returned packing's bits < 32 says which: a 32-bit key. Nothing listed (low > high): plain.
inline DepthKeyPacking single_sort_packing(uint32_t low, uint32_t high, uint32_t tiles) {
  if (low > high) return plain_key_packing();
  const int room = 32 - tile_key_bits(tiles);
  int need = 0;  // bits of high - low
  while (need < 32 && ((high - low) >> need) != 0u) ++need;
  if (need <= room) return {low, need, 0};
  if (need - room <= kMaxDepthShift) return {low, room, need - room};
  return plain_key_packing();
}
// Whether `p` makes 32-bit keys.
constexpr bool is_narrow(const DepthKeyPacking& p) { return p.bits < 32; }

}  // namespace catgs::fm
