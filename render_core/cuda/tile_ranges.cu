// Stage 4: per-tile [start, end) ranges of the sorted render list (mirrors
// src/cpu/tile_ranges.cpp): an entry whose tile differs from its left (right) neighbour starts
// (ends) that tile's range. Grid-stride, 64-bit indices: the list may pass 2^31 entries (the
// renderer refuses lists past 2^32 - 1, the limit of the 32-bit ranges).
#include "cuda_check.h"
#include "stages.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

__global__ void __launch_bounds__(tune::kEntryThreads)
tile_ranges_kernel(const uint64_t* keys,  // [L] sorted
                   uint64_t entries, uint32_t tiles,
                   uint2* ranges) {       // [tiles], zeroed
  const uint64_t stride = static_cast<uint64_t>(gridDim.x) * blockDim.x;
  for (uint64_t i = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < entries;
       i += stride) {
    const auto tile = static_cast<uint32_t>(keys[i] >> 32);
    if (tile >= tiles) continue;  // sentinel
    if (i == 0 || static_cast<uint32_t>(keys[i - 1] >> 32) != tile)
      ranges[tile].x = static_cast<uint32_t>(i);
    if (i + 1 == entries || static_cast<uint32_t>(keys[i + 1] >> 32) != tile)
      ranges[tile].y = static_cast<uint32_t>(i + 1);
  }
}

}  // namespace

void tile_ranges(const uint64_t* sorted_keys, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream) {
  CATGS_CUDA(cudaMemsetAsync(ranges, 0, sizeof(uint2) * tiles, stream));
  if (entries == 0) return;
  const uint64_t want = (entries + tune::kEntryThreads - 1) / tune::kEntryThreads;
  const auto blocks = static_cast<unsigned>(want < tune::kMaxEntryBlocks ? want : tune::kMaxEntryBlocks);
  tile_ranges_kernel<<<blocks, tune::kEntryThreads, 0, stream>>>(sorted_keys, entries, tiles, ranges);
  CATGS_CUDA_LAUNCHED("tile_ranges_kernel");
}

}  // namespace catgs::cuda::stages
