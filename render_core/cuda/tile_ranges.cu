// Stage 4: per-tile [start, end) ranges of the sorted render list (mirrors
// cpu/tile_ranges.cpp): an entry whose tile differs from its left (right) neighbour starts
// (ends) that tile's range. Grid-stride, 64-bit indices: the list may pass 2^31 entries (the
// renderer refuses lists past 2^32 - 1, the limit of the 32-bit ranges).
#include <cub/device/device_radix_sort.cuh>

#include "cuda_check.h"
#include "tile_ranges.h"
#include "tunables.h"

namespace catgs::cuda::stages {

namespace {

// The tile of a sorted key: the part above the packed depth of [tile | depth], or the whole
// tile-only key.
struct PackedTile {
  DepthKeyPacking packing;
  __device__ uint32_t operator()(uint64_t key) const { return packing.tile_of(key); }
};
struct WholeTile {
  __device__ uint32_t operator()(uint32_t key) const { return key; }
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

// Heaviest tiles first: keys = entries of each tile, values = tile ids.
__global__ void tile_loads_kernel(const uint2* __restrict__ ranges,  // [tiles]
                                  uint32_t tiles,
                                  uint32_t* __restrict__ loads,  // [tiles]
                                  uint32_t* __restrict__ ids) {  // [tiles]
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= tiles) return;
  loads[t] = ranges[t].y - ranges[t].x;
  ids[t] = t;
}

}  // namespace

std::size_t tile_order_temp_bytes(uint32_t tiles) {
  std::size_t bytes = 0;
  CATGS_CUDA(cub::DeviceRadixSort::SortPairsDescending(nullptr, bytes, static_cast<uint32_t*>(nullptr),
                                                       static_cast<uint32_t*>(nullptr), static_cast<uint32_t*>(nullptr),
                                                       static_cast<uint32_t*>(nullptr), tiles));
  return bytes;
}

void order_tiles(const uint2* ranges, uint32_t tiles, uint64_t entries, uint32_t* scratch, uint32_t* order, void* temp,
                 std::size_t temp_bytes, cudaStream_t stream) {
  uint32_t* loads = scratch;
  uint32_t* sorted_loads = scratch + tiles;
  uint32_t* ids = scratch + 2 * static_cast<std::size_t>(tiles);
  tile_loads_kernel<<<(tiles + 255) / 256, 256, 0, stream>>>(ranges, tiles, loads, ids);
  CATGS_CUDA_LAUNCHED("tile_loads_kernel");
  int bits = 1;  // a tile holds at most `entries`: sort only the bits that can be set
  while (bits < 32 && (entries >> bits) != 0) ++bits;
  CATGS_CUDA(cub::DeviceRadixSort::SortPairsDescending(temp, temp_bytes, loads, sorted_loads, ids, order, tiles, 0,
                                                       bits, stream));
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
  launch_tile_ranges(sorted_keys, entries, tiles, PackedTile{packing}, ranges, stream);
}

void tile_ranges(const uint32_t* sorted_tile_keys, uint64_t entries, uint32_t tiles, uint2* ranges,
                 cudaStream_t stream) {
  launch_tile_ranges(sorted_tile_keys, entries, tiles, WholeTile{}, ranges, stream);
}

}  // namespace catgs::cuda::stages
