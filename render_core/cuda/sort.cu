// Stage 3: sort the render list by its keys (mirrors cpu/sort.cpp). CUB's radix sort is stable,
// so equal keys keep emission order, which is Gaussian index order, as the CPU reference's pair
// sort does. Only the key's bits are visited: the 32-bit [tile | quantised depth] of the single
// sort (forward_model/key_packing.h; 32 bits, 4 passes of 8 at 1920x1080) or, where a frame's
// depth range does not fit it, the plain 64-bit [tile | depth] (45 bits at 1080p, 6 passes).
// With the depth-first sort (depth_order.cu) the list arrives in depth order and only its
// bit_width(tiles) tile bits are sorted (2 passes at 1080p).
#include <cub/device/device_radix_sort.cuh>

#include "base/cuda_check.h"
#include "sort.h"

namespace catgs::cuda::stages {

namespace {

// CUB picks its offset type from num_items' width (cub/detail/choose_offset.cuh): 32-bit offsets
// for a 32-bit count. On sm_90 its onesweep pass then takes 23 pairs of 32-bit keys and values a
// thread instead of 17 with 64-bit offsets (tuning_radix_sort.cuh): fewer, larger tiles, which
// suits lists of a few million entries (docs/history/render_core_sort_and_keys.md, "32-bit sort
// offsets, key emission past big runs, ..."). Lists past 2^31 - 1
// entries keep 64-bit offsets (GPU test row list>2^31).
bool narrow_offsets(uint64_t entries) { return entries <= 0x7fffffffull; }

template <typename Key, typename Count>
cudaError_t radix_sort(void* temp, std::size_t& bytes, cub::DoubleBuffer<Key>& k, cub::DoubleBuffer<uint32_t>& v,
                       Count entries, int key_bits, cudaStream_t stream) {
  return cub::DeviceRadixSort::SortPairs(temp, bytes, k, v, entries, 0, key_bits, stream);
}

template <typename Key>
std::size_t temp_bytes_for(uint64_t entries, int key_bits) {
  std::size_t bytes = 0;
  cub::DoubleBuffer<Key> k(nullptr, nullptr);
  cub::DoubleBuffer<uint32_t> v(nullptr, nullptr);
  if (narrow_offsets(entries))
    CATGS_CUDA(radix_sort(nullptr, bytes, k, v, static_cast<uint32_t>(entries), key_bits, nullptr));
  else
    CATGS_CUDA(radix_sort(nullptr, bytes, k, v, entries, key_bits, nullptr));
  return bytes;
}

template <typename Key>
int sort_with(Key* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp, std::size_t temp_bytes,
              cudaStream_t stream) {
  if (entries == 0) return 0;
  cub::DoubleBuffer<Key> k(keys[0], keys[1]);
  cub::DoubleBuffer<uint32_t> v(values[0], values[1]);
  if (narrow_offsets(entries))
    CATGS_CUDA(radix_sort(temp, temp_bytes, k, v, static_cast<uint32_t>(entries), key_bits, stream));
  else
    CATGS_CUDA(radix_sort(temp, temp_bytes, k, v, entries, key_bits, stream));
  return k.selector;
}

}  // namespace

std::size_t sort_temp_bytes(uint64_t entries, int key_bits) { return temp_bytes_for<uint64_t>(entries, key_bits); }

int sort_pairs(uint64_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
               std::size_t temp_bytes, cudaStream_t stream) {
  return sort_with(keys, values, entries, key_bits, temp, temp_bytes, stream);
}

std::size_t sort_narrow_temp_bytes(uint64_t entries, int key_bits) {
  return temp_bytes_for<uint32_t>(entries, key_bits);
}

int sort_pairs_narrow(uint32_t* keys[2], uint32_t* values[2], uint64_t entries, int key_bits, void* temp,
                      std::size_t temp_bytes, cudaStream_t stream) {
  return sort_with(keys, values, entries, key_bits, temp, temp_bytes, stream);
}

}  // namespace catgs::cuda::stages
