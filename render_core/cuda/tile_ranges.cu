// Stage 4: per-tile [start, end) ranges of the sorted render list (mirrors
// cpu/tile_ranges.cpp): an entry whose tile differs from its left (right) neighbour starts
// (ends) that tile's range. Grid-stride, 64-bit indices: the list may pass 2^31 entries (the
// renderer refuses lists past 2^32 - 1, the limit of the 32-bit ranges).
#include "base/cuda_check.h"
#include "load_bucket.cuh"
#include "tile_ranges.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// The tile of a sorted key: the part above its depth (forward_model/key_packing.h), for 64-bit
// and 32-bit keys.
struct TileOfKey {
  DepthKeyPacking packing;
  __device__ uint32_t operator()(uint64_t key) const { return packing.tile_of(key); }
  __device__ uint32_t operator()(uint32_t key) const { return packing.tile_of32(key); }
};

template <typename Key, typename TileOf>
__global__ void __launch_bounds__(tune::kEntryThreads)
    tile_ranges_kernel(const Key* __restrict__ keys,  // [L] sorted
                       uint64_t entries, uint32_t tiles, TileOf tile_of,
                       uint2* __restrict__ ranges) {  // [tiles], zeroed
  const uint64_t stride = static_cast<uint64_t>(gridDim.x) * blockDim.x;
  for (uint64_t i = static_cast<uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < entries; i += stride) {
    const uint32_t tile = tile_of(keys[i]);
    if (tile >= tiles) continue;  // sentinel
    if (i == 0 || tile_of(keys[i - 1]) != tile) ranges[tile].x = static_cast<uint32_t>(i);
    if (i + 1 == entries || tile_of(keys[i + 1]) != tile) ranges[tile].y = static_cast<uint32_t>(i + 1);
  }
}

// Heaviest tiles first, to within a quarter of an octave (load_bucket.cuh). Within a bucket the
// order is whatever the shared-memory atomics give: the image does not depend on the order of the
// tiles, only the kernel's tail does. One block does it all (a 1080p frame has 8160 tiles): a
// histogram in shared memory, a scan of its counts, then a scatter.
constexpr int kOrderThreads = 1024;

__global__ void __launch_bounds__(kOrderThreads) order_tiles_kernel(const uint2* __restrict__ ranges,  // [tiles]
                                                                    uint32_t tiles,
                                                                    uint32_t* __restrict__ order,       // [tiles]
                                                                    uint32_t* __restrict__ heaviest) {  // [1]
  __shared__ unsigned count[kLoadBuckets], next[kLoadBuckets], most;
  for (auto b = static_cast<int>(threadIdx.x); b < kLoadBuckets; b += static_cast<int>(blockDim.x)) count[b] = 0;
  if (threadIdx.x == 0) most = 0;
  __syncthreads();
  for (uint32_t t = threadIdx.x; t < tiles; t += blockDim.x) {
    const uint32_t load = ranges[t].y - ranges[t].x;
    atomicAdd(&count[load_bucket(load)], 1u);
    atomicMax(&most, load);
  }
  __syncthreads();
  if (threadIdx.x == 0) {
    buckets_from_heaviest(count, next);
    *heaviest = most;
  }
  __syncthreads();
  for (uint32_t t = threadIdx.x; t < tiles; t += blockDim.x) {
    const uint32_t load = ranges[t].y - ranges[t].x;
    order[atomicAdd(&next[load_bucket(load)], 1u)] = t;
  }
}

}  // namespace

void order_tiles(const uint2* ranges, uint32_t tiles, uint32_t* order, uint32_t* heaviest, cudaStream_t stream) {
  order_tiles_kernel<<<1, kOrderThreads, 0, stream>>>(ranges, tiles, order, heaviest);
  CATGS_CUDA_LAUNCHED("order_tiles_kernel");
}

namespace {

template <typename Key, typename TileOf>
void launch_tile_ranges(const Key* sorted_keys, uint64_t entries, uint32_t tiles, TileOf tile_of, uint2* ranges,
                        cudaStream_t stream) {
  CATGS_CUDA(cudaMemsetAsync(ranges, 0, sizeof(uint2) * tiles, stream));
  if (entries == 0) return;
  const uint64_t want = (entries + tune::kEntryThreads - 1) / tune::kEntryThreads;
  const auto blocks = static_cast<unsigned>(want < tune::kMaxEntryBlocks ? want : tune::kMaxEntryBlocks);
  tile_ranges_kernel<<<blocks, tune::kEntryThreads, 0, stream>>>(sorted_keys, entries, tiles, tile_of, ranges);
  CATGS_CUDA_LAUNCHED("tile_ranges_kernel");
}

}  // namespace

void tile_ranges(const uint64_t* sorted_keys, DepthKeyPacking packing, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream) {
  launch_tile_ranges(sorted_keys, entries, tiles, TileOfKey{packing}, ranges, stream);
}

void tile_ranges(const uint32_t* sorted_keys, DepthKeyPacking packing, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream) {
  launch_tile_ranges(sorted_keys, entries, tiles, TileOfKey{packing}, ranges, stream);
}

}  // namespace catgs::cuda::stages
