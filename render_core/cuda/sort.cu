// Stage 3: sort the render list by [tile | depth] (mirrors cpu/sort.cpp). CUB's radix sort is
// stable, so equal keys (one Gaussian cannot repeat a tile; equal depths in one tile can happen)
// keep emission order, which is Gaussian index order, as the CPU reference's pair sort does.
// Only the key's bits are visited: bit_width(tiles) + the packed depth's (records.h
// DepthKeyPacking; 32 for the plain key: 45 bits, 6 passes of 8, at 1920x1080, instead of 64). With the depth-first sort (depth_order.cu) the list arrives in depth order
// and only its bit_width(tiles) tile bits are sorted (2 passes at 1080p).
#include <cub/device/device_radix_sort.cuh>

#include "cuda_check.h"
#include "sort.h"

namespace catgs::cuda::stages {

std::size_t sort_temp_bytes(uint64_t entries, int key_bits) {
  std::size_t bytes = 0;
  cub::DoubleBuffer<uint64_t> k(nullptr, nullptr);
  cub::DoubleBuffer<uint32_t> v(nullptr, nullptr);
  // 64-bit num_items: CUB picks 64-bit offsets, so lists past 2^31 entries sort correctly.
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(nullptr, bytes, k, v, entries, 0, key_bits));
  return bytes;
}

int sort_pairs(uint64_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
               std::size_t temp_bytes, cudaStream_t stream) {
  if (entries == 0) return 0;
  cub::DoubleBuffer<uint64_t> k(keys[0], keys[1]);
  cub::DoubleBuffer<uint32_t> v(values[0], values[1]);
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(temp, temp_bytes, k, v, entries, 0, key_bits, stream));
  return k.selector;
}

std::size_t sort_by_tile_temp_bytes(uint64_t entries, int key_bits) {
  std::size_t bytes = 0;
  cub::DoubleBuffer<uint32_t> k(nullptr, nullptr), v(nullptr, nullptr);
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(nullptr, bytes, k, v, entries, 0, key_bits));
  return bytes;
}

int sort_pairs_by_tile(uint32_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
                       std::size_t temp_bytes, cudaStream_t stream) {
  if (entries == 0) return 0;
  cub::DoubleBuffer<uint32_t> k(keys[0], keys[1]), v(values[0], values[1]);
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(temp, temp_bytes, k, v, entries, 0, key_bits, stream));
  return k.selector;
}

}  // namespace catgs::cuda::stages
