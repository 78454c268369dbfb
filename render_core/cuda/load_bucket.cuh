// Loads sorted to within a quarter of an octave, for the one-block schedulers that put the
// heaviest work first (tile_ranges.cu order_tiles, task_split.cu plan_slices): a load L goes to
// bucket 4 floor(log2 L) + (the two bits of L below its leading one) + 1 (bucket 0: empty), and
// the buckets are laid out from the highest down. A load at most 1.19x lighter than the one
// before it costs nothing in a kernel's tail, and a histogram of 129 counts in shared memory is
// far cheaper than a radix sort's launches (docs/history/render_core_task_split.md, "Tile order by
// load buckets").
#pragma once

#include <cstdint>

namespace catgs::cuda::stages {

inline constexpr int kLoadBuckets = 4 * 32 + 1;

__device__ __forceinline__ int load_bucket(uint32_t load) {
  if (load == 0u) return 0;
  const int octave = 31 - __clz(load);  // floor(log2 load)
  const uint32_t quarter = octave >= 2 ? (load >> (octave - 2)) & 3u : (load << (2 - octave)) & 3u;
  return 4 * octave + static_cast<int>(quarter) + 1;
}

// Thread 0 of a block: next[b] = where bucket b's first item goes, buckets from the highest down
// (a serial scan: 129 counts).
__device__ __forceinline__ void buckets_from_heaviest(const unsigned* count, unsigned* next) {
  unsigned at = 0;
  for (int b = kLoadBuckets - 1; b >= 0; --b) {
    next[b] = at;
    at += count[b];
  }
}

}  // namespace catgs::cuda::stages
