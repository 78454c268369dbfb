// Stage 3: sort the render list by its keys (mirrors cpu/sort.cpp). CUB's radix sort is stable,
// so equal keys keep emission order, which is Gaussian index order, as the CPU reference's pair
// sort does. Only the key's bits are visited: the 32-bit [tile | quantised depth] of the single
// sort (forward_model/key_packing.h; 32 bits, 4 passes of 8 at 1920x1080) or, where a frame's
// depth range does not fit it, the plain 64-bit [tile | depth] (45 bits at 1080p, 6 passes).
// With the depth-first sort (depth_order.cu) the list arrives in depth order and only its
// bit_width(tiles) tile bits are sorted (2 passes at 1080p).
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

std::size_t sort_narrow_temp_bytes(uint64_t entries, int key_bits) {
  std::size_t bytes = 0;
  cub::DoubleBuffer<uint32_t> k(nullptr, nullptr), v(nullptr, nullptr);
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(nullptr, bytes, k, v, entries, 0, key_bits));
  return bytes;
}

int sort_pairs_narrow(uint32_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
                      std::size_t temp_bytes, cudaStream_t stream) {
  if (entries == 0) return 0;
  cub::DoubleBuffer<uint32_t> k(keys[0], keys[1]), v(values[0], values[1]);
  CATGS_CUDA(cub::DeviceRadixSort::SortPairs(temp, temp_bytes, k, v, entries, 0, key_bits, stream));
  return k.selector;
}

}  // namespace catgs::cuda::stages
